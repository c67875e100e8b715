"""A small seeded scene with every table filled, for the adapter tests (not a test module)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from framechain.config.chain import ChainConfig
from framechain.timeline import (
    CameraTable,
    DepthFrameTable,
    JointStateTable,
    ObservationTable,
    PointTable,
    Timeline,
    TransformTable,
)

T0 = 1_700_000_000_000_000_000
CHAIN = ChainConfig.from_dict({
    "frames": {"camera": "camera_optical_frame", "body": "base_link", "world": "map"},
    "topics": {"camera_info": "/camera/color/camera_info", "detections": "/detections",
               "depth": "/camera/depth/image_rect_raw"},
    "evidence": {"hops": {"world": "/debug/point_world"}, "target": "/grasp_target", "reference": "/mocap/target"},
})
#: Camera 0.3 m ahead of and 0.8 m above base_link, optical axes (REP-103: x right, y down, z forward).
OPTICAL_Q = np.array([-0.5, 0.5, -0.5, 0.5])
K = {"fx": 600.0, "fy": 600.0, "cx": 320.0, "cy": 240.0}
W, H = 64, 48


def body_pose(t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """map -> base_link: a robot driving along x at 0.5 m/s while yawing slowly."""
    xyz = np.column_stack([1.0 + 0.5 * t_s, 0.5 + 0.1 * np.sin(t_s), np.zeros_like(t_s)])
    q = Rotation.from_euler("z", (0.2 * t_s)[:, None]).as_quat()
    return xyz, q


def make_scene(rng: np.random.Generator, *, n_tf: int = 40, n_obs: int = 6) -> Timeline:
    t_s = np.arange(n_tf) * 0.05
    stamps = T0 + np.rint(t_s * 1e9).astype(np.int64)
    delay = rng.integers(1_000_000, 5_000_000, size=n_tf)
    xyz, q = body_pose(t_s)
    odom = TransformTable.from_rows("odom", "base_link", stamps, xyz, q, log_time_ns=stamps + delay, source="/tf")
    map_odom = TransformTable.from_rows("map", "odom", stamps[::4], np.zeros((len(stamps[::4]), 3)),
                                        np.tile([0, 0, 0, 1.0], (len(stamps[::4]), 1)),
                                        log_time_ns=stamps[::4] + 7_000_000, source="/tf")
    mount = TransformTable.from_rows("base_link", "camera_link", [T0], [0.3, 0.0, 0.8], [0, 0, 0, 1.0],
                                     log_time_ns=[T0], is_static=True, source="/tf_static")
    optical = TransformTable.from_rows("camera_link", "camera_optical_frame", [T0], [0, 0, 0], OPTICAL_Q,
                                       log_time_ns=[T0], is_static=True, source="/tf_static")
    transforms = TransformTable.concat([mount, optical, odom, map_odom])
    cameras = CameraTable.from_intrinsics("camera_optical_frame", **K, width=W, height=H, stamp_ns=T0,
                                          distortion=[0.1, -0.05, 0.001, 0.002, 0.0],
                                          source="/camera/color/camera_info")
    obs_t = stamps[5 : 5 + 2 * n_obs : 2]
    obs = ObservationTable(
        obs_id=np.arange(n_obs) + 10, stamp_ns=obs_t, log_time_ns=obs_t + 20_000_000,
        camera_frame=np.full(n_obs, "camera_optical_frame"), u=rng.uniform(5, W - 5, n_obs),
        v=rng.uniform(5, H - 5, n_obs), depth_m=np.where(np.arange(n_obs) % 3 == 0, 1.25, np.nan),
        label=np.array(["cup", "", "bowl", "cup", "cup", "can"][:n_obs]), score=rng.uniform(0.5, 1.0, n_obs),
        source=np.full(n_obs, "/detections"),
    )
    # Depth: a tilted plane 1-3 m away, a hole of zeros; millimetre values so 16UC1 is exact.
    yy, xx = np.mgrid[0:H, 0:W]
    images = []
    for k in range(3):
        d = np.round(1.0 + 0.02 * xx + 0.01 * yy + 0.1 * k, 3).astype(np.float32)
        d[:4, :4] = 0.0
        images.append(d)
    depth_t = stamps[[4, 12, 20]]
    depth = DepthFrameTable.from_arrays("camera_optical_frame", depth_t, np.stack(images),
                                        source="/camera/depth/image_rect_raw")
    import dataclasses

    depth = dataclasses.replace(depth, log_time_ns=depth_t + 3_000_000, encoding=np.full(3, "16UC1"))
    depth = dataclasses.replace(depth, loader=lambda i: images[i])
    pts_t = obs_t[:3]
    points = PointTable(
        frame=np.array(["map", "map", "map", "map"]), stamp_ns=np.append(pts_t, T0 + 10**9),
        log_time_ns=np.append(pts_t + 25_000_000, T0 + 10**9),
        xyz=rng.normal(size=(4, 3)), quat_xyzw=np.vstack([np.full((3, 4), np.nan), [[0, 0, 0, 1.0]]]),
        role=np.array(["hop_world", "hop_world", "target", "reference"]), obs_id=np.full(4, -1),
        source=np.array(["/debug/point_world", "/debug/point_world", "/grasp_target", "/mocap/target"]),
    )
    js_t = stamps[::5]
    names = ["j1", "j2"]
    joints = JointStateTable(
        stamp_ns=np.repeat(js_t, 2), log_time_ns=np.repeat(js_t + 1_000_000, 2),
        joint=np.tile(names, len(js_t)), position=rng.normal(size=2 * len(js_t)),
        velocity=rng.normal(size=2 * len(js_t)), effort=np.full(2 * len(js_t), np.nan),
        source=np.full(2 * len(js_t), "/joint_states"),
    )
    return Timeline(transforms=transforms, cameras=cameras, observations=obs, joint_states=joints, points=points,
                    depth_frames=depth)
