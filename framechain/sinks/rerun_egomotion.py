"""The cameras' own motion in Rerun: every camera's video under its pinhole, and its rotation rate from the images
against the rate forward kinematics predicts, as series (a time offset shows as a shift between the curves).

What it adds to a recording (:mod:`framechain.sinks.rerun`):

- ``/cameras/<camera>``: each camera other than the chain's (which is ``/camera``) as a ``Pinhole``
  under its optical frame, its video as ``AssetVideo`` with one ``VideoFrameReference`` per frame
  (decoded by the viewer) under its image plane; the chain camera's video under ``/camera/video``
  when the replay logged none (an episode without detections);
- ``/series/rotation_rate_deg_s/<camera>/{measured,declared,corrected}``: the magnitude of the
  camera's rotation rate per pair of consecutive frames, measured from its images, predicted by
  forward kinematics through the declared link, mount and time, and through the fitted ones (the legend: measured,
  as declared, as fitted; one plot per camera in the default layout);
  ``.../x|y|z/{measured,declared}`` the rate's components in the optical frame (the declared mount:
  a mount error shows as a misfit of the components, not of the magnitude). Stamped at the middle of
  the pair on ``sensor_time``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from framechain.analysis.egomotion.curves import RotationRateCurves
from framechain.analysis.run import Run
from framechain.sinks.colors import AS_RUN_COLOR, CORRECTED_COLOR
from framechain.sinks.rerun_common import IMAGE_PLANE_SUFFIX, Clock, entity_part
from framechain.timeline import Timeline

if TYPE_CHECKING:
    import rerun as rr

__all__ = ["RATE_ENTITY", "camera_root", "log_camera_motion", "log_camera_videos"]

RATE_ENTITY = "/series/rotation_rate_deg_s"
#: The legend's: what ran (the kinematics as declared) orange, corrected purple; the images' own measure neutral.
_COLOURS = {"measured": (40, 40, 40), "declared": AS_RUN_COLOR, "corrected": CORRECTED_COLOR}
_LEGEND = {"measured": "measured (images)", "declared": "forward kinematics, as declared",
           "corrected": "forward kinematics, as fitted"}


def camera_name(frame: str) -> str:
    return frame.removesuffix("_optical_frame").removesuffix("_optical") or frame


def camera_root(frame: str) -> str:
    """The entity root of a camera other than the chain's (``/cameras/<camera>``)."""
    return f"/cameras/{entity_part(camera_name(frame))}"


def log_camera_videos(rec: rr.RecordingStream, run: Run, clock: Clock, rows: dict[str, int]) -> None:
    """Every other camera's pinhole and video; the chain camera's video when the replay logged none."""
    import rerun as rr

    timeline = run.timeline
    chain_camera = run.replay.frames.camera
    cams = timeline.cameras
    for frame in (str(f) for f in dict.fromkeys(cams.frame.tolist())):
        if frame == chain_camera:
            if not any(k.startswith("/camera/video") for k in rows):
                _log_video(rec, timeline, clock, frame, "/camera/video", rows)
            continue
        entity = camera_root(frame)
        i = int(np.flatnonzero(cams.frame == frame)[0])
        rec.log(entity, rr.Pinhole(image_from_camera=cams.K[i], resolution=[float(cams.width[i]),
                                                                          float(cams.height[i])],
                                   camera_xyz=rr.ViewCoordinates.RDF, parent_frame=frame,
                                   child_frame=frame + IMAGE_PLANE_SUFFIX, image_plane_distance=0.3), static=True)
        rows[entity] = 1
        _log_video(rec, timeline, clock, frame, f"{entity}/video", rows)


def _log_video(rec: rr.RecordingStream, timeline: Timeline, clock: Clock, frame: str, entity: str,
               rows: dict[str, int]) -> None:
    """The camera's video frames as references into its mp4 (the first file of its rows)."""
    import rerun as rr

    images = timeline.image_frames
    mine = np.flatnonzero((images.frame == frame) & images.video_frames)
    if mine.size == 0:
        return
    path = str(images.video_path[mine[0]])
    mine = mine[images.video_path[mine] == path]
    mine = mine[np.argsort(images.stamp_ns[mine], kind="stable")]
    rec.log(entity, rr.AssetVideo(path=path), rr.CoordinateFrame(frame + IMAGE_PLANE_SUFFIX), static=True)
    rec.send_columns(entity, indexes=clock.columns(images.stamp_ns[mine], images.log_time_ns[mine]),
                     columns=rr.VideoFrameReference.columns_nanos(images.video_time_ns[mine]))
    rows[entity] = int(mine.size)


def log_camera_motion(rec: rr.RecordingStream, run: Run, clock: Clock, rows: dict[str, int]) -> None:
    """Each measured camera's rotation rate: from its images, as declared, as fitted (see the module docstring)."""
    for curves in run.rotation_rates:
        _log_rates(rec, curves, clock, rows)


def _log_rates(rec: rr.RecordingStream, curves: RotationRateCurves, clock: Clock, rows: dict[str, int]) -> None:
    import rerun as rr

    base = f"{RATE_ENTITY}/{entity_part(camera_name(curves.camera))}"
    series = {"measured": curves.measured, "declared": curves.declared, "corrected": curves.fitted}
    for name, rates in series.items():
        entities = {f"{base}/{name}": rates.magnitude_deg_s}
        if name != "corrected":
            entities.update({f"{base}/{axis}/{name}": rates.components_deg_s[:, k] for k, axis in enumerate("xyz")})
        for entity, column in entities.items():
            ok = np.isfinite(column)
            label = _LEGEND[name]
            rec.log(entity, rr.SeriesLines(colors=[_COLOURS[name]], names=[label]), static=True)
            rec.send_columns(entity, indexes=clock.columns(curves.middle_ns[ok]),
                             columns=rr.Scalars.columns(scalars=column[ok]))
            rows[entity] = int(ok.sum())
