"""Markers (ArUco, AprilTag) found in a LeRobot camera's frames, as observations: static-target evidence.

The ``evidence.markers`` path of ROS images (:mod:`framechain.vision.markers`) on a
dataset's video (or image-in-Parquet) frames: each frame of the camera is decoded (grey), searched
with OpenCV's ArucoDetector, and each marker becomes a detection stamped with the camera's time of
its frame, its log time the state row's; the corners are then resolved with the camera's model
(square-marker PnP with ``size_m``, else a bearing) as for any tag
(:func:`~framechain.adapters.messages.fiducials.resolve_fiducials`).

A long episode is searched on every k-th frame (at most ``max_frames``), and a note says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from framechain.adapters.messages.egomotion_frames import camera_image_rows, decode_grey
from framechain.adapters.messages.fiducials import FiducialRows, ResolvedFiducials, resolve_fiducials, tag_size_lookup
from framechain.config.chain_cameras import MarkerSpec
from framechain.timeline import CameraTable, ImageFrameTable
from framechain.vision.markers import MarkerFinder

__all__ = ["VideoMarkers", "video_markers"]

#: At most this many frames of an episode are searched.
MAX_MARKER_FRAMES = 900


@dataclass(frozen=True)
class VideoMarkers:
    """The markers found in a camera's frames, resolved into observation rows, and what was searched."""

    resolved: ResolvedFiducials
    notes: tuple[str, ...]


def video_markers(images: ImageFrameTable, cameras: CameraTable, camera: str, spec: MarkerSpec, *, source: str,
                  max_frames: int = MAX_MARKER_FRAMES) -> VideoMarkers:
    """Search camera ``camera``'s frames (``source``: the dataset feature they come from) for ``spec``'s markers."""
    rows = camera_image_rows(images, camera)
    step = max(1, math.ceil(rows.size / max_frames))
    searched = rows[::step]
    notes = []
    if step > 1:
        notes.append(f"{source}: markers searched in every {step}th frame ({searched.size} of {rows.size})")
    fiducials = FiducialRows(size_for_marker=tag_size_lookup(spec.size_m))
    finder = MarkerFinder(spec.dictionary, fiducials)
    grey, missing, _decoded = decode_grey(images, searched)
    for k in np.flatnonzero(~missing).tolist():
        row = int(searched[k])
        finder.search(source, int(images.log_time_ns[row]), int(images.stamp_ns[row]), camera, grey[k])
    notes.extend(finder.notes())
    if missing.any():
        notes.append(f"{source}: {int(missing.sum())} of {searched.size} frames could not be decoded for markers")
    resolved = resolve_fiducials(fiducials, cameras)
    return VideoMarkers(resolved=resolved, notes=(*notes, *resolved.notes))
