"""The tilt lab: what a translation-only extrinsic costs, swept over camera pitch and depth.

A camera on a mast is pitched down by ``pitch``; the robot's extrinsic keeps the mount's
translation and the optical rotation but loses the pitch. A point straight ahead of the lens at
z-depth ``depth_m`` lands ``2 Z sin(pitch / 2)`` (about ``Z sin(pitch)``) away from where the
full extrinsic puts it. The sweep runs the real replay on a generated timeline, so it exercises
the same code as a log.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from framechain.config.chain import ChainFrames
from framechain.geometry.conventions import OPTICAL_FROM_LINK_QUAT_XYZW
from framechain.geometry.rotations import quat_from_rpy
from framechain.replay import replay
from framechain.timeline import CameraTable, ObservationTable, Timeline, TransformTable

MOUNT_XYZ = (0.30, 0.0, 0.80)


@dataclass(frozen=True)
class TiltRow:
    pitch_deg: float
    depth_m: float
    error_m: float


def tilt_sweep(pitches_deg: Sequence[float], depths_m: Sequence[float]) -> list[TiltRow]:
    """World-frame error of the translation-only extrinsic against the full one, per pitch and depth."""
    pitch = np.repeat(np.asarray(pitches_deg, dtype=float), len(depths_m))
    depth = np.tile(np.asarray(depths_m, dtype=float), len(pitches_deg))
    n = pitch.size
    stamps = np.arange(n, dtype=np.int64) * 1_000_000  # one observation per (pitch, depth), 1 ms apart
    camera = CameraTable.from_intrinsics("camera_optical_frame", fx=600, fy=600, cx=320, cy=240, width=640, height=480)
    observations = ObservationTable(
        obs_id=np.arange(n),
        stamp_ns=stamps,
        log_time_ns=stamps,
        camera_frame=np.full(n, "camera_optical_frame"),
        u=np.full(n, 320.0),
        v=np.full(n, 240.0),
        depth_m=depth,
        label=np.full(n, "tilt"),
        score=np.ones(n),
        source=np.full(n, "lab"),
    )
    fixed = TransformTable.concat(
        [
            TransformTable.from_rows("map", "base_link", [0], [[0.0, 0.0, 0.0]], [[0, 0, 0, 1.0]], is_static=True),
            TransformTable.from_rows(
                "camera_link",
                "camera_optical_frame",
                [0],
                [[0.0, 0.0, 0.0]],
                [OPTICAL_FROM_LINK_QUAT_XYZW],
                is_static=True,
            ),
        ]
    )
    frames = ChainFrames(camera="camera_optical_frame", body="base_link", world="map")
    worlds = []
    for mount_pitch in (pitch, np.zeros(n)):  # the full extrinsic, then the one that lost its pitch
        mount = TransformTable.from_rows(
            "base_link",
            "camera_link",
            stamps,
            np.tile(MOUNT_XYZ, (n, 1)),
            quat_from_rpy(np.stack([np.zeros(n), np.deg2rad(mount_pitch), np.zeros(n)])).T,
        )
        timeline = Timeline(transforms=TransformTable.concat([fixed, mount]), cameras=camera, observations=observations)
        worlds.append(replay(timeline, frames).p_world)
    error = np.linalg.norm(worlds[0] - worlds[1], axis=1)
    return [TiltRow(float(p), float(d), float(e)) for p, d, e in zip(pitch, depth, error, strict=True)]


def crossing_pitch_deg(rows: Sequence[TiltRow], depth_m: float, tolerance_m: float) -> float | None:
    """The smallest pitch at which the error at ``depth_m`` exceeds ``tolerance_m`` (linear interp.)."""
    sel = sorted((r for r in rows if np.isclose(r.depth_m, depth_m)), key=lambda r: r.pitch_deg)
    for a, b in itertools.pairwise(sel):
        if a.error_m <= tolerance_m < b.error_m:
            return a.pitch_deg + (tolerance_m - a.error_m) / (b.error_m - a.error_m) * (b.pitch_deg - a.pitch_deg)
    return None
