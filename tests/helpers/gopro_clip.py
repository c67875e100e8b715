"""A GoPro clip as framechain's camera-motion evidence: its gyro as the "link", its frames as the camera.

The gyro (:mod:`gpmf`) measures the camera body's rate; integrated, it is the body's rotation over
time, the role forward kinematics plays for a camera on a robot link. The frames are decoded with
framechain's video reader and measured with its tracker, rotation only (no translation prior).

Intrinsics are guessed, as GoPro writes none. Near the image centre a fisheye maps an angle
``theta`` off the axis to a radius ``f theta``; :func:`gopro_intrinsics` takes ``f`` from a
horizontal field of view, ``f = (W / 2) / (HFOV / 2)`` (radians), as an equidistant fisheye or as a
pinhole with that focal (right at the centre, too long towards the edges), or the pinhole that spans
the field (``(W / 2) / tan(HFOV / 2)``, too short everywhere but the edges). GoPro publishes about
118 deg across for the Hero5's wide mode; karma.mp4's final pan moves the image by about 550 px per
radian of gyro turn at the centre and at both sides alike (equidistant-like, about 89 deg across),
so it was not shot in wide mode (the file's settings atom is undocumented).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt

from framechain.adapters.lerobot.video import probe_video, read_frames
from framechain.analysis.egomotion import LinkMotion
from framechain.arrays import FloatArray, IntArray
from framechain.config.calibration import Intrinsics
from framechain.geometry.rotations import quat_from_rotvec, quat_multiply
from framechain.timeline import EgoMotionTable
from framechain.vision.egomotion import EgoMotionOptions, FeatureTracks, measure_egomotion, track_features
from tests.helpers.gpmf import SensorStream, axes_matrix

#: The link name the gyro's orientation goes by.
GYRO_LINK = "gopro_gyro"
#: GoPro Hero5 Black, wide mode, 16:9: horizontal field of view (GoPro's published figure, rounded).
HERO5_WIDE_HFOV_DEG = 118.0
#: The optical frame (x right, y down, z forward) in GoPro's IMU axes (X left, Y out of the back, Z up):
#: columns are the optical axes.
GOPRO_FROM_OPTICAL = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]])

Lens = Literal["equidistant", "centre_pinhole", "width_pinhole"]


def documented_mount(axis_order: str) -> FloatArray:
    """``R_gyro_cam`` (3, 3) GoPro's documentation predicts for gyro channels named by ``axis_order``.

    The gyro's channels are GoPro axes in ``axis_order`` (:func:`gpmf.axes_matrix`); the camera frame
    is the optical frame. A vector ``v_cam`` reads ``R_gyro_cam v_cam`` in the gyro's channels.
    """
    out: FloatArray = axes_matrix(axis_order).T @ GOPRO_FROM_OPTICAL
    return out


def integrate_rates(times_s: FloatArray, rates: FloatArray) -> FloatArray:
    """Orientations ``R_start_body(t)`` (N, 4) xyzw from body-frame rates (N, 3) rad/s at ``times_s`` (N,).

    Between two samples the body turns by the mean of their rates times the gap; the increments are
    chained with a log-depth prefix product (vectorised: 13 passes for 5,000 samples).
    """
    mean_rate = 0.5 * (rates[1:] + rates[:-1])
    steps = quat_from_rotvec((mean_rate * np.diff(times_s)[:, None]).T)
    quat = np.concatenate([np.array([[0.0], [0.0], [0.0], [1.0]]), steps], axis=1)
    shift = 1
    while shift < quat.shape[1]:
        quat[:, shift:] = quat_multiply(quat[:, :-shift], quat[:, shift:])
        shift *= 2
    out: FloatArray = (quat / np.linalg.norm(quat, axis=0)).T
    return out


def gyro_link(gyro: SensorStream, *, bias_rad_s: npt.ArrayLike | None = None, link: str = GYRO_LINK) -> LinkMotion:
    """The gyro's integrated orientation as a :class:`LinkMotion` (stamps in ns on the video's clock).

    Axes are the gyro's channels as GPMF stores them (``gyro.axis_order`` names them); ``bias_rad_s``
    (3,) is subtracted from every sample first.
    """
    rates = gyro.values - (np.zeros(3) if bias_rad_s is None else np.asarray(bias_rad_s, dtype=float))
    stamps = np.round(gyro.times_s * 1e9).astype(np.int64)
    return LinkMotion(link, stamps, integrate_rates(gyro.times_s, rates))


@dataclass(frozen=True)
class ClipFrames:
    """A clip's frames, grey ``(N, H, W)``, at their presentation times (ns on the video's clock)."""

    images: npt.NDArray[np.uint8]
    stamps_ns: IntArray


def decode_clip(path: str | Path, *, start_s: float = 0.0, stop_s: float = float("inf")) -> ClipFrames:
    """The frames of the clip's first video stream presented in ``[start_s, stop_s)``, grey, with their times."""
    info = probe_video(path)
    times_s = np.arange(info.frames) / info.fps
    wanted = np.round(times_s[(times_s >= start_s) & (times_s < stop_s)] * 1e9).astype(np.int64)
    frames = read_frames(path, wanted)
    if not frames.usable.all():
        raise ValueError(f"{path}: {int((~frames.usable).sum())} frames missing, repeated or black")
    return ClipFrames(images=frames.row_images(), stamps_ns=frames.frame_time_ns)


def gopro_intrinsics(width: int, height: int, *, lens: Lens = "equidistant",
                     hfov_deg: float = HERO5_WIDE_HFOV_DEG) -> Intrinsics:
    """A guessed camera model for a GoPro frame ``width`` x ``height`` spanning ``hfov_deg`` (module text)."""
    half = np.deg2rad(hfov_deg) / 2.0
    focal = (width / 2.0) / (np.tan(half) if lens == "width_pinhole" else half)
    model, distortion = ("equidistant", (0.0, 0.0, 0.0, 0.0)) if lens == "equidistant" else ("plumb_bob", ())
    return Intrinsics(fx=float(focal), fy=float(focal), cx=(width - 1) / 2.0, cy=(height - 1) / 2.0, width=width,
                      height=height, distortion_model=model, distortion=distortion,
                      source=f"guess: {lens}, {hfov_deg:g} deg across")


def clip_tracks(frames: ClipFrames, options: EgoMotionOptions | None = None) -> FeatureTracks:
    """Feature tracks through every frame (framechain's tracker)."""
    return track_features(frames.images, options=options)


def clip_motion(tracks: FeatureTracks, frames: ClipFrames, intrinsics: Intrinsics,
                options: EgoMotionOptions | None = None) -> EgoMotionTable:
    """The camera's rotation between frame pairs, rotation only (no translation prior)."""
    return measure_egomotion(tracks, frames.stamps_ns, intrinsics, frame="gopro_optical", options=options)
