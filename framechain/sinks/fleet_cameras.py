"""The fleet report's section on each recording's cameras: one link and one mount per camera across the episodes,
each episode's offset with its interval, and the episodes that depart from the recording (and why).

Drawn from the recording-level fits (:mod:`framechain.fleet.recordings`), which the sinks only render.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from framechain.analysis.egomotion.findings import yaml_mount
from framechain.analysis.egomotion.recording import CameraRecordingFit
from framechain.sinks.colors import BOUND_COLOR, CORRECTED_COLOR, ERROR_COLOR, hex_color
from framechain.sinks.document import Block, FigureBlock, Heading, Paragraph, Section, table
from framechain.sinks.plots import Figure, figure_png, new_figure

__all__ = ["camera_figures", "camera_summary", "cameras_sections"]

COLUMNS = ("episode", "link", "offset", "95% interval", "mount from the recording's", "departs")

Recordings = Mapping[str, Sequence[CameraRecordingFit]]


def camera_summary(log: str, fit: CameraRecordingFit) -> str:
    """One camera's recording-level fit in one sentence: what it rests on, and every episode left out and why."""
    fitted = len(fit.episodes)
    left = "" if not fit.left_out else "; left out: " + "; ".join(
        f"episode {episode} ({why})" for episode, why in fit.left_out)
    if not fit.explained:
        return (f"{log}, camera {fit.camera}: the model explains its motion in none of the {fitted} episode(s) "
                f"measured: no link, mount or offset for the recording{left}.")
    high = fit.mount_interval_deg[1]
    mount = (f"its mount known to {high:.1f} deg (95%, resampling episodes)" if np.isfinite(high)
             else "mount from one episode")
    declared = ("" if not np.isfinite(fit.mount_from_declared_deg)
                else f", {fit.mount_from_declared_deg:.1f} deg from the declared one")
    moved = "" if fit.link == fit.declared_link else f" (declared on {fit.declared_link})"
    axes = "" if not fit.unobservable_axes else (
        "; about " + ", ".join("[" + ", ".join(f"{v:.2f}" for v in a) + "]" for a in fit.unobservable_axes)
        + f" in {fit.link} the mount is not observable (kept as declared)")
    departs = len({d.episode for d in fit.departures})
    position = "" if fit.xyz_link_cam is None else (
        f"; its position, not known, fitted at [{', '.join(f'{v:.3f}' for v in fit.xyz_link_cam)}] m (the median of "
        f"{fit.position_episodes} episode(s), the farthest {fit.position_spread_m * 1e3:.1f} mm from it)")
    return (f"{log}, camera {fit.camera}: rides {fit.link}{moved} in the fit of {fitted} episode(s); "
            f"{mount}{declared}{axes}{position}; median offset {fit.median_offset_s * 1e3:+.1f} ms; "
            f"{departs} episode(s) depart{left}.")


def recording_fix(fit: CameraRecordingFit, robot_yaml: str) -> str:
    """For a camera whose position was fitted from its images (a robot.yaml framechain made, the camera's mount on
    an optical frame): its mount, position, focal length and offset over the recording, as the keys of
    ``robot_yaml`` to set ("" for any other camera, or one the model explains in no episode)."""
    if fit.xyz_link_cam is None or not fit.explained or not fit.name:
        return ""
    key = f"cameras.{fit.name}"
    mount = yaml_mount(fit.link, fit.q_link_cam, tuple(float(v) for v in fit.xyz_link_cam), None)
    focal = "" if not np.isfinite(fit.focal_px) else (f", {key}.intrinsics.fx: {fit.focal_px:.1f} and "
                                                        f"{key}.intrinsics.fy: {fit.focal_px:.1f}")
    return (f"In {robot_yaml}, set {key}.mount: {mount}{focal}, {key}.timing.offset_s: {fit.median_offset_s:.3f} "
            "(the recording's fit of "
            f"{len(fit.explained)} episode(s): its mount, the median position, focal length and offset).")


def _rows(fit: CameraRecordingFit) -> list[list[str]]:
    why: dict[int, list[str]] = {}
    for d in fit.departures:
        why.setdefault(d.episode, []).append(d.why)
    rows = []
    for e in fit.episodes:
        angle = fit.episode_mount_deg.get(e.episode)
        low, high = e.offset_interval_s
        rows.append([str(e.episode), e.link, f"{e.offset_s * 1e3:+.1f} ms", f"{low * 1e3:+.1f} .. {high * 1e3:+.1f} ms",
                     "" if angle is None else f"{angle:.1f} deg", "; ".join(why.get(e.episode, [])) or "no"])
    rows += [[str(episode), "-", "-", "-", "", f"left out: {reason}"] for episode, reason in fit.left_out]
    return sorted(rows, key=lambda row: int(row[0]))


def cameras_sections(recordings: Recordings, figures: Sequence[Figure] = ()) -> list[Section]:
    """The fleet report's section on each recording's cameras (none without recordings)."""
    if not recordings:
        return []
    blocks: list[Block] = [FigureBlock(f) for f in figures]
    for log, fits in recordings.items():
        for fit in fits:
            blocks += [Paragraph(camera_summary(log, fit)), table(COLUMNS, _rows(fit))]
    return [Section(Heading("Cameras across each recording's episodes"), tuple(blocks), compact=True)]


def camera_figures(recordings: Recordings) -> list[Figure]:
    """Per recording, each camera's offset per episode with its 95% interval (departing episodes in red), the
    median as a line: one panel per camera."""
    out = []
    for k, (log, fits) in enumerate(recordings.items()):
        fig, axes = new_figure(max(4.2 * len(fits), 4.8), 3.2, columns=len(fits), top="title")
        for ax, fit in zip(axes, fits, strict=True):
            departing = {d.episode for d in fit.departures}
            for e in fit.episodes:
                low, high = e.offset_interval_s
                colour = hex_color(ERROR_COLOR if e.episode in departing else CORRECTED_COLOR)
                # An estimate a hair outside its interval (the interval's coarser search: 6 us seen) draws no bar
                # on that side; matplotlib refuses a negative one.
                spread = [[max(e.offset_s - low, 0.0) * 1e3], [max(high - e.offset_s, 0.0) * 1e3]]
                ax.errorbar([e.episode], [e.offset_s * 1e3], yerr=spread, fmt="o", color=colour, ms=4, capsize=2)
            ax.axhline(fit.median_offset_s * 1e3, color=hex_color(BOUND_COLOR), ls="--", lw=1)
            ax.set_xlabel("episode")
            ax.set_ylabel("video/state offset (ms)")
            ax.locator_params(axis="x", integer=True)
            ax.set_title(f"{fit.camera} on {fit.link}", fontsize=8)
            ax.grid(True, alpha=0.3)
        out.append(figure_png(fig, f"fleet_camera_offsets_{k}", f"{log}: each camera's offset per episode, with its "
                              "95% interval (red: the episode departs from the recording), the median dashed"))
    return out
