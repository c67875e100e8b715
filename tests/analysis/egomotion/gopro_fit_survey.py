"""The camera-motion fit on the real GoPro clips, gyro as the only candidate link: the numbers, reproducible.

Not a test: ``.venv/bin/python -m tests.analysis.egomotion.gopro_fit_survey [--hfov 89] [--lens equidistant]``
prints, per clip window and fit options, what :func:`framechain.analysis.egomotion.fit_camera_motion`
returns (offset and interval, mount, focal scale, observability) beside plain residuals computed
here: the RMS rotation angle per frame pair of ``B`` against ``X^T A X`` (the measured camera
rotation against the gyro's, carried by the mount ``X``) at a given mount and offset. Then the
gyro's bias: its mean over the part where the camera barely turns, and that mean less the turn the
sea horizon shows (the horizon is a great circle whose normal, "up", stays fixed in the world).
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial.transform import Rotation

from framechain.analysis.egomotion import EgoMotionFitOptions, LinkMotion, fit_camera_motion, rotation_rates
from framechain.arrays import FloatArray
from framechain.config.calibration import Intrinsics
from framechain.timeline import EgoMotionTable
from framechain.vision.opencv import undistort_normalised
from tests.helpers.gopro_clip import (
    ClipFrames,
    Lens,
    clip_motion,
    clip_tracks,
    decode_clip,
    documented_mount,
    gopro_intrinsics,
    gyro_link,
)
from tests.helpers.gpmf import read_stream
from tests.helpers.realdata import GOPRO_CLIPS, REALDATA

CLIPS = REALDATA / GOPRO_CLIPS
#: (clip, window name, from s, to s)
CASES = (("karma.mp4", "whole", 0.0, 99.0), ("karma.mp4", "first half (gimbal still)", 0.0, 6.04),
         ("karma.mp4", "final pan 10.9 s-end", 10.9, 99.0), ("max-heromode.mp4", "whole", 0.0, 99.0))


def signed_permutations() -> list[FloatArray]:
    """The 24 rotations that permute the axes and flip signs."""
    out = []
    for order, signs in itertools.product(itertools.permutations(range(3)), itertools.product((1.0, -1.0), repeat=3)):
        matrix = np.zeros((3, 3))
        matrix[np.arange(3), order] = signs
        if np.linalg.det(matrix) > 0:
            out.append(matrix)
    return out


def angle_deg(a: FloatArray, b: FloatArray) -> float:
    return float(np.rad2deg(Rotation.from_matrix(a.T @ b).magnitude()))


def describe(mount: FloatArray) -> str:
    """``R_gyro_cam`` as "optical axis = signed gyro channel" (its largest entry per column)."""
    rows = np.argmax(np.abs(mount), axis=0)
    return " ".join(f"{axis}={'+' if mount[row, i] > 0 else '-'}ch{row}" for i, (axis, row) in enumerate(zip(
        "xyz", rows, strict=True)))


def plain_residual_deg(table: EgoMotionTable, link: LinkMotion, mount: FloatArray, offset_s: float) -> float:
    """RMS angle per frame pair of the measured rotation against the gyro's carried by ``mount`` at ``offset_s``."""
    rates = rotation_rates(table, link, Rotation.from_matrix(mount).as_quat(), offset_s)
    angle = rates.residual * (table.stamp1_ns - table.stamp0_ns) * 1e-9
    return float(np.rad2deg(np.sqrt(np.nanmean(angle**2))))


def survey_case(table: EgoMotionTable, link: LinkMotion, documented: FloatArray, max_offset_s: float) -> str:
    fit = fit_camera_motion(lambda _prior, **_options: table, [link], camera="gopro", declared_link=link.link,
                            declared_q_link_cam=np.array([0.0, 0.0, 0.0, 1.0]),
                            options=EgoMotionFitOptions(max_offset_s=max_offset_s))
    if not fit.links:
        return f"    max_offset {max_offset_s}: no fit ({'; '.join(fit.notes)})"
    mount = Rotation.from_quat(fit.q_link_cam).as_matrix()
    nearest = min(signed_permutations(), key=lambda p: angle_deg(p, mount))
    lo, hi = fit.offset_interval_s
    return "\n".join((
        f"    max_offset {max_offset_s}: {fit.links[0].pairs} pairs; camera turns {fit.camera_rotation_deg:.3f}, "
        f"gyro {fit.links[0].link_rotation_deg:.3f} deg RMS per pair",
        f"      offset {fit.offset_s * 1e3:.1f} ms [{lo * 1e3:.1f}, {hi * 1e3:.1f}] "
        f"(observable {fit.offset_observable}); focal scale {fit.focal_scale:.3f} "
        f"[{fit.focal_scale_interval[0]:.3f}, {fit.focal_scale_interval[1]:.3f}]",
        f"      mount {angle_deg(documented, mount):.1f} deg from documented, {angle_deg(nearest, mount):.1f} deg from"
        f" {describe(nearest)} (observable {fit.mount_observable})",
        f"      residual deg/pair: identity mount at 0 s {plain_residual_deg(table, link, np.eye(3), 0.0):.3f}, "
        f"documented at 0 s {plain_residual_deg(table, link, documented, 0.0):.3f}, fit robust "
        f"{fit.links[0].residual_deg:.3f}, fit plain {plain_residual_deg(table, link, mount, fit.offset_s):.3f}",
        *(f"      note: {note}" for note in fit.notes)))


def horizon_up(frames: ClipFrames, intrinsics: Intrinsics) -> FloatArray:
    """Per frame, the normal of the sea horizon (up, optical frame): karma.mp4's horizon left of its centre."""
    columns = np.arange(5, 320, 29)
    strips = np.stack([frames.images[:, 205:275, c:c + 29].astype(float).mean(axis=2) for c in columns], axis=2)
    strips = gaussian_filter1d(strips, 1.5, axis=1)
    step = -np.diff(strips, axis=1)  # sky (bright) over sea (darker): the strongest fall down the strip
    row = np.clip(np.argmax(step, axis=1), 1, step.shape[1] - 2)
    below, at, above = (np.take_along_axis(step, (row + k)[:, None], axis=1)[:, 0] for k in (-1, 0, 1))
    curvature = below - 2.0 * at + above
    rows = 205.5 + row + np.where(curvature < 0, 0.5 * (below - above) / np.where(curvature < 0, curvature, 1), 0)
    pixels = np.stack([np.broadcast_to(columns + 14.5, rows.shape), rows], axis=-1).reshape(-1, 2)
    rays = np.concatenate([undistort_normalised(intrinsics.camera_model(), pixels), np.ones((len(pixels), 1))], axis=1)
    rays = (rays / np.linalg.norm(rays, axis=1, keepdims=True)).reshape(*rows.shape, 3)
    normals = np.linalg.svd(rays)[2][:, -1]
    out: FloatArray = normals * np.sign(-normals[:, 1])[:, None]
    return out


def karma_bias(frames: ClipFrames, intrinsics: Intrinsics, windows: tuple[tuple[float, float], ...]) -> list[str]:
    gyro = read_stream(CLIPS / "karma.mp4", "GYRO")
    up = horizon_up(frames, intrinsics)
    times = frames.stamps_ns * 1e-9
    to_optical = documented_mount(gyro.axis_order).T
    lines = []
    for start, stop in windows:
        inside = (times >= start) & (times <= stop)
        mean = np.rad2deg(gyro.values[(gyro.times_s >= start) & (gyro.times_s <= stop)].mean(axis=0))
        drift = np.array([np.polyfit(times[inside], up[inside, i], 1)[0] for i in range(3)])
        normal = up[inside].mean(axis=0) / np.linalg.norm(up[inside].mean(axis=0))
        turn = -np.rad2deg(np.cross(normal, drift))  # dn/dt = -w x n: the turn across "up"
        across = to_optical @ mean - normal * (normal @ to_optical @ mean)
        lines.append(f"    {start:.1f}-{stop:.1f} s: gyro mean (ch0..2) {np.round(mean, 3)} deg/s, "
                     f"|{np.linalg.norm(mean):.2f}|; horizon turn (optical) {np.round(turn, 3)}; "
                     f"bias across up (optical) "
                     f"{np.round(across - turn, 3)}, |{np.linalg.norm(across - turn):.2f}| deg/s")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hfov", type=float, default=89.0, help="horizontal field of view (deg)")
    parser.add_argument("--lens", default="equidistant", choices=("equidistant", "centre_pinhole", "width_pinhole"))
    args = parser.parse_args()
    lens: Lens = args.lens
    decoded: dict[str, tuple[ClipFrames, EgoMotionTable, Intrinsics]] = {}
    for name in sorted({case[0] for case in CASES}):
        frames = decode_clip(CLIPS / name)
        intrinsics = gopro_intrinsics(frames.images.shape[2], frames.images.shape[1], lens=lens, hfov_deg=args.hfov)
        decoded[name] = (frames, clip_motion(clip_tracks(frames), frames, intrinsics), intrinsics)
    for name, window, start, stop in CASES:
        gyro = read_stream(CLIPS / name, "GYRO")
        table = decoded[name][1]
        t0, t1 = table.stamp0_ns * 1e-9, table.stamp1_ns * 1e-9
        part = table.take(np.flatnonzero((t0 >= start) & (t1 <= stop)))
        print(f"{name} {window} ({args.lens}, {args.hfov:g} deg, f {decoded[name][2].fx:.0f} px)")
        for max_offset in (0.5, 0.1):
            print(survey_case(part, gyro_link(gyro), documented_mount(gyro.axis_order), max_offset))
    print("karma.mp4 gyro bias")
    karma_frames, _table, karma_intrinsics = decoded["karma.mp4"]
    print("\n".join(karma_bias(karma_frames, karma_intrinsics, ((0.0, 6.04), (6.0, 11.4), (0.0, 11.4)))))


if __name__ == "__main__":
    main()
