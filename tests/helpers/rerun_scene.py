"""A hand-built timeline for the Rerun sink and replay command tests, the robot's own hop points beside it, and its
run, replayed only, with findings handed to the sinks.

The scene: a base driving at 0.5 m/s with a slow yaw under ``map -> odom``, a mast camera pitched down 30 deg, depth
images at 20 Hz and seven detections (five that replay, one outside the image, one after the odometry ends).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.analysis.run import Run
from framechain.analysis.verdict.attribute import Attribution, Finding
from framechain.config.chain import ChainConfig, ChainEvidence, ChainFrames
from framechain.replay import ReplayResult, replay
from framechain.timeline import CameraTable, DepthFrameTable, ObservationTable, PointTable, Timeline, TransformTable

T0 = 1_700_000_000_000_000_000
MS = 1_000_000
FRAMES = ChainFrames(camera="camera_optical_frame", body="base_link", world="map")
OPTICAL_QUAT_XYZW = [-0.5, 0.5, -0.5, 0.5]  # camera_link (FLU) -> optical (RDF), REP-103
MAP_FROM_ODOM_T = np.array([0.5, -0.2, 0.0])
MAP_FROM_ODOM = Rotation.from_euler("z", 10, degrees=True)
BODY_OFFSET = np.array([0.05, 0.0, 0.0])  # the robot's body point is off by 5 cm (as-run fault)
TARGET_OFFSET = np.array([0.0, 0.03, 0.0])


def mast_camera_timeline() -> Timeline:
    """A base driving at 0.5 m/s with a slow yaw, a mast camera pitched down 30 deg, depth at 20 Hz.

    Observations: five good ones (depth from images or inline), one outside the image, one after the
    odometry ends (extrapolation).
    """
    stamps = T0 + np.arange(0, 2001, 20) * MS  # odom -> base_link at 50 Hz for 2 s
    t_s = (stamps - T0) / 1e9
    yaw = 0.2 * t_s
    odom_base = TransformTable.from_rows(
        "odom", "base_link", stamps, np.stack([0.5 * t_s, 0.1 * t_s, np.zeros_like(t_s)], axis=1),
        Rotation.from_euler("z", yaw[:, None]).as_quat(), log_time_ns=stamps + 3 * MS, source="/tf",
    )
    statics = TransformTable.concat([
        TransformTable.from_rows("map", "odom", [T0], [MAP_FROM_ODOM_T], [MAP_FROM_ODOM.as_quat()],
                                 is_static=True, source="/tf_static"),
        TransformTable.from_rows("base_link", "mast_link", [T0], [[0.2, 0.0, 1.2]],
                                 [Rotation.from_euler("y", 30, degrees=True).as_quat()],
                                 is_static=True, source="/tf_static"),
        TransformTable.from_rows("mast_link", "camera_optical_frame", [T0], [[0.05, 0.0, 0.0]],
                                 [OPTICAL_QUAT_XYZW], is_static=True, source="/tf_static"),
    ])
    camera = CameraTable.from_intrinsics(
        "camera_optical_frame", fx=150, fy=150, cx=80, cy=60, width=160, height=120, stamp_ns=T0,
    )
    depth_stamps = T0 + np.arange(0, 2001, 50) * MS
    yy, xx = np.mgrid[0:120, 0:160]
    base = (1.5 + 0.002 * xx + 0.001 * yy).astype(np.float32)
    images = np.stack([base + 0.01 * k for k in range(depth_stamps.size)])
    depth = DepthFrameTable.from_arrays("camera_optical_frame", depth_stamps, images, source="/depth")
    obs_stamps = T0 + np.array([200, 500, 800, 1100, 1400, 1700, 2500]) * MS
    n = obs_stamps.size
    observations = ObservationTable(
        obs_id=np.arange(100, 100 + n), stamp_ns=obs_stamps, log_time_ns=obs_stamps + 40 * MS,
        camera_frame=np.full(n, "camera_optical_frame"),
        u=np.array([80.0, 95.0, 70.0, 88.0, 400.0, 60.0, 80.0]),
        v=np.array([60.0, 50.0, 72.0, 66.0, 60.0, 40.0, 60.0]),
        depth_m=np.array([np.nan, np.nan, 1.8, np.nan, np.nan, 1.6, 1.5]),
        label=np.full(n, "cup"), score=np.full(n, 0.9), source=np.full(n, "/detections"),
    )
    return Timeline(transforms=TransformTable.concat([odom_base, statics]), cameras=camera,
                    observations=observations, depth_frames=depth, metadata={"source": "test scene"})


def with_as_run(timeline: Timeline, result: ReplayResult) -> Timeline:
    """The robot's own hop points: camera exact, body (and so world) off by BODY_OFFSET.

    Matched by obs_id for camera and body; by stamp (obs_id -1) for world, which is logged in
    ``odom`` to exercise the frame conversion; a target off by TARGET_OFFSET, and a reference.
    """
    ok = np.flatnonzero(result.replayed)
    obs = result.observations
    m = ok.size
    world = result.p_world[ok] + BODY_OFFSET  # world_from_body here has the base's yaw: keep it simple
    world_in_odom = MAP_FROM_ODOM.inv().apply(world - MAP_FROM_ODOM_T)

    def rows(frame: str, xyz: Any, role: str, obs_id: Any, stamp_shift_ns: int = 0) -> PointTable:
        stamps = obs.stamp_ns[ok] + stamp_shift_ns
        return PointTable(
            frame=np.full(m, frame), stamp_ns=stamps, log_time_ns=stamps + 5 * MS, xyz=xyz,
            quat_xyzw=np.full((m, 4), np.nan), role=np.full(m, role), obs_id=obs_id, source=np.full(m, "/debug"),
        )

    points = PointTable.concat([
        rows("camera_optical_frame", result.p_cam[ok], "hop_camera", obs.obs_id[ok]),
        rows("base_link", result.p_body[ok] + BODY_OFFSET, "hop_body", obs.obs_id[ok]),
        rows("odom", world_in_odom, "hop_world", np.full(m, -1), stamp_shift_ns=200_000),
        rows("map", result.p_world[ok] + TARGET_OFFSET, "target", obs.obs_id[ok]),
    ])
    return timeline.replace(points=points)


def recorded_timeline() -> Timeline:
    """The scene as a robot that logs its own hop points records it (:func:`with_as_run`)."""
    timeline = mast_camera_timeline()
    return with_as_run(timeline, replay(timeline, FRAMES))


def replayed_run(timeline: Timeline, *, findings: list[Finding] | None = None,
                 reference_point: tuple[float, float, float] | None = None) -> Run:
    """The run of a hand-built timeline through FRAMES, replayed only; ``findings`` handed to the sinks as if
    an attribution had found them (the sinks draw them; nothing else of the attribution is read)."""
    chain = ChainConfig(frames=FRAMES, evidence=ChainEvidence(reference_point=reference_point))
    made = pipeline.run(timeline, chain, attribute=False)
    if findings is None:
        return made
    n = int(made.replay.replayed.sum())
    found = Attribution(
        source={}, config=chain, replay=made.replay, inputs=None, metric="none",  # type: ignore[arg-type]
        error_before=np.full(n, np.nan), error_after=np.full(n, np.nan), hop_errors={},
        evidence_points=np.full((n, 3), np.nan), corrected_world=np.full((n, 3), np.nan), findings=tuple(findings),
        seed=0, aligned=made.aligned,
    )
    return replace(made, attribution=found, not_attributed=None)
