"""A wrist-camera scene for the LeRobot tests, with ground truth computed by yourdfpy.

The 6-joint test arm (data/arm6.urdf) moves each joint along ``q0 + A sin(w t + phi)``; a wrist
camera (640x480, fx = fy = 500) hangs on ``flange_link`` through an FLU camera_link; a static
world point sits about 0.45 m in front of the camera at t = 0. Ground-truth camera poses come from
yourdfpy's ``get_transform`` and hand-built matrices, never from framechain, so the tests compare
framechain against independent values. Dataset state: arm joints in degrees, the gripper 0-100.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset

HERE = Path(__file__).resolve().parent
DATA = HERE / "data"
ARM6 = DATA / "arm6.urdf"
ARM_JOINTS = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_yaw", "wrist_roll")
STATE_NAMES = [f"{j}.pos" for j in ARM_JOINTS] + ["gripper.pos"]
FPS = 30
FX = FY = 500.0
CX, CY = 320.0, 240.0
WIDTH, HEIGHT = 640, 480
FINGER_UPPER_M = 0.04  # finger_left limit in arm6.urdf
WORLD_FROM_BASE_XYZ = (0.5, -0.2, 0.05)
WORLD_FROM_BASE_YAW = 0.3
MOUNT_XYZ = (0.01, -0.02, 0.05)
MOUNT_RPY = (0.1, -1.45, 0.05)
#: Optical (x right, y down, z forward) axes in camera_link (x forward, y left, z up): REP-103.
LINK_FROM_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

FloatArray = npt.NDArray[np.float64]

Q0 = np.array([0.2, 0.5, -0.7, 0.4, 0.3, -0.2])
AMP = np.array([0.10, 0.06, 0.08, 0.10, 0.07, 0.12])
OMEGA = np.array([1.3, 0.9, 1.7, 2.1, 1.1, 2.5])
PHASE = np.array([0.0, 0.4, 1.1, -0.3, 0.8, 2.0])


def rx(a: float) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def ry(a: float) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rz(a: float) -> FloatArray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def homogeneous(R: FloatArray, t: Sequence[float]) -> FloatArray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def arm_q_rad(t_s: npt.ArrayLike) -> FloatArray:
    """(T, 6) arm joint angles in radians at times ``t_s``."""
    t = np.asarray(t_s, dtype=float)[:, None]
    out: FloatArray = Q0 + AMP * np.sin(OMEGA * t + PHASE)
    return out


def gripper_pct(t_s: npt.ArrayLike) -> FloatArray:
    out: FloatArray = 50.0 + 30.0 * np.sin(0.8 * np.asarray(t_s, dtype=float))
    return out


def state_vectors(t_s: npt.ArrayLike) -> FloatArray:
    """(T, 7) dataset state: arm in degrees, gripper 0-100."""
    return np.hstack([np.rad2deg(arm_q_rad(t_s)), gripper_pct(t_s)[:, None]])


@cache
def _urdf() -> Any:
    import yourdfpy

    return yourdfpy.URDF.load(str(ARM6), load_meshes=False, build_collision_scene_graph=False)


def world_from_base() -> FloatArray:
    return homogeneous(rz(WORLD_FROM_BASE_YAW), WORLD_FROM_BASE_XYZ)


def flange_from_optical() -> FloatArray:
    """Mount (URDF rpy: R = Rz(yaw) Ry(pitch) Rx(roll)) times the REP-103 optical rotation."""
    r, p, y = MOUNT_RPY
    link = homogeneous(rz(y) @ ry(p) @ rx(r), MOUNT_XYZ)
    return link @ homogeneous(LINK_FROM_OPTICAL, (0.0, 0.0, 0.0))


def base_from_link_truth(link: str, t_s: npt.ArrayLike, *, stored: bool = False) -> FloatArray:
    """(T, 4, 4) ``T_base_link`` from yourdfpy at times ``t_s``.

    ``stored``: use the joint values as the dataset stores them (float32 degrees and percent),
    for comparisons at the frames themselves; otherwise the continuous motion.
    """
    urdf = _urdf()
    if stored:
        state = state_vectors(t_s).astype(np.float32).astype(np.float64)
        q, g = state[:, :6] * np.pi / 180.0, state[:, 6] / 100.0 * FINGER_UPPER_M
    else:
        q = arm_q_rad(t_s)
        g = gripper_pct(t_s) / 100.0 * FINGER_UPPER_M
    out = np.empty((q.shape[0], 4, 4))
    for i in range(q.shape[0]):
        cfg = dict(zip(ARM_JOINTS, q[i], strict=True))
        cfg["finger_left"] = g[i]
        urdf.update_cfg(cfg)
        out[i] = urdf.get_transform(frame_to=link, frame_from="base_link")
    return out


def base_from_optical_truth(t_s: npt.ArrayLike, *, stored: bool = False) -> FloatArray:
    out: FloatArray = base_from_link_truth("flange_link", t_s, stored=stored) @ flange_from_optical()
    return out


def target_world() -> FloatArray:
    """A static point about 0.45 m in front of the camera at t = 0, a little off-centre."""
    T = world_from_base() @ base_from_optical_truth(np.array([0.0]))[0]
    out: FloatArray = (T @ np.array([0.03, -0.02, 0.45, 1.0]))[:3]
    return out


def project_truth(t_s: npt.ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(u, v, depth_m) of the target in the camera at times ``t_s``."""
    T_world_opt = world_from_base() @ base_from_optical_truth(t_s)
    p = np.linalg.inv(T_world_opt) @ np.append(target_world(), 1.0)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    return FX * x / z + CX, FY * y / z + CY, z


@dataclass(frozen=True)
class ArmDataset:
    root: Path
    lengths: tuple[int, ...]
    camera_delay_s: float
    timestamps: tuple[FloatArray, ...]  # per episode, frame times (s) as written
    camera_times: tuple[FloatArray, ...] = ()  # per episode, when the camera took each frame (s)


def write_arm_dataset(
    root: Path,
    *,
    version: str,
    lengths: Sequence[int] = (24, 40, 30),
    camera_delay_s: float = 0.0,
    camera_timestamp_column: bool = False,
    detection_feature: bool = False,
    episodes_per_file: int | None = None,
    depth: bool = False,
    jitter_s: float = 0.0,
    seed: int = 0,
    start_s: float = 0.0,
    wall_clock_s: float | None = None,
) -> ArmDataset:
    """Write the arm dataset; each episode starts at a different phase of the motion.

    The camera takes frame k at ``t_k + camera_delay_s``; with ``camera_timestamp_column`` that
    time is recorded in ``observation.images.wrist.timestamp``. The detection feature holds
    (u, v, depth) of the target at the camera's true time. ``jitter_s`` makes the recording
    variable-rate: frame times and each camera frame's delay wander by up to that much (seeded). ``start_s``:
    the first row's timestamp (GR00T's datasets start at 0.05 s); ``wall_clock_s``: a per-frame column of Unix
    times (s, float64) ``observation.unix_time``, the first row's at that time.
    """
    rng = np.random.default_rng(seed)
    features: dict[str, FeatureSpec] = {
        "observation.state": FeatureSpec("float32", (7,), STATE_NAMES),
        "action": FeatureSpec("float32", (7,), STATE_NAMES),
        "observation.images.wrist": FeatureSpec(
            "video", (HEIGHT, WIDTH, 3), ["height", "width", "channels"],
            {"video.fps": FPS, "video.codec": "av1", "video.is_depth_map": False},
        ),
    }
    if camera_timestamp_column:
        features["observation.images.wrist.timestamp"] = FeatureSpec("float64", (1,), None)
    if detection_feature:
        features["observation.detection.wrist"] = FeatureSpec("float32", (3,), ["u", "v", "depth_m"])
    if depth:
        features["observation.depth.wrist"] = FeatureSpec("uint16", (DEPTH_H, DEPTH_W), ["height", "width"])
    if wall_clock_s is not None:
        features["observation.unix_time"] = FeatureSpec("float64", (1,), None)
    episodes = []
    stamps = []
    camera_times = []
    for e, n in enumerate(lengths):
        t = episode_times(e, n)
        if jitter_s:
            t = np.cumsum(np.r_[0.0, 1.0 / FPS + rng.uniform(-jitter_s, jitter_s, n - 1)])
            t = t.astype(np.float32).astype(np.float64)
        if start_s:
            t = (t + start_s).astype(np.float32).astype(np.float64)
        frames: dict[str, Any] = {"observation.state": state_vectors(t), "action": state_vectors(t + 0.05)}
        if wall_clock_s is not None:
            frames["observation.unix_time"] = wall_clock_s + (t - t[0])
        t_cam = t + camera_delay_s + (rng.uniform(-jitter_s, jitter_s, n) if jitter_s else 0.0)
        if camera_timestamp_column:
            frames["observation.images.wrist.timestamp"] = t_cam
        if detection_feature or depth:
            u, v, z = project_truth(t_cam)
            if detection_feature:
                det = np.stack([u, v, z], axis=1)
                det[::5] = np.nan  # every fifth frame: nothing detected
                frames["observation.detection.wrist"] = det
            if depth:
                frames["observation.depth.wrist"] = np.broadcast_to(
                    np.round(z * 1000.0)[:, None, None], (n, DEPTH_H, DEPTH_W)).astype(np.uint16)
        episodes.append(EpisodeData(frames, task=f"reach {e % 2}", timestamp_s=t if jitter_s or start_s else None))
        stamps.append(t)
        camera_times.append(t_cam)
    # A seven-joint arm of its own (with a wrist yaw): no robot type framechain bundles a URDF for.
    write_lerobot_dataset(root, episodes, features=features, fps=FPS, version=version,
                          episodes_per_file=episodes_per_file, robot_type="seven_joint_test_arm")
    return ArmDataset(root, tuple(lengths), camera_delay_s, tuple(stamps), tuple(camera_times))


#: Depth images of the depth test (a small camera keeps the Parquet small).
DEPTH_W, DEPTH_H = 64, 48


def episode_times(e: int, n: int) -> FloatArray:
    """Frame times of episode ``e`` as the dataset stores them (float32, restarting at 0).

    Every episode replays the same motion from t = 0, as LeRobot timestamps restart each episode.
    """
    out: FloatArray = (np.arange(n) / FPS).astype(np.float32).astype(np.float64)
    return out


def write_robot_yaml(
    folder: Path,
    *,
    timing: dict[str, Any] | None = None,
    detections: list[dict[str, Any]] | None = None,
    depth_camera: bool = False,
    chain: dict[str, Any] | None = None,
) -> Path:
    """robot.yaml + calib/wrist.yaml for the arm in ``folder``; returns the robot.yaml path."""
    calib: dict[str, Any] = {
        "name": "wrist",
        "intrinsics": {"fx": FX, "fy": FY, "cx": CX, "cy": CY, "width": WIDTH, "height": HEIGHT},
        "mount": {"parent": "flange_link", "xyz": list(MOUNT_XYZ), "rpy": list(MOUNT_RPY), "optical": False},
        "video_key": "observation.images.wrist",
    }
    if depth_camera:
        scale = DEPTH_W / WIDTH
        calib["intrinsics"] = {"fx": FX * scale, "fy": FY * scale, "cx": CX * scale, "cy": CY * scale,
                               "width": DEPTH_W, "height": DEPTH_H}
        calib["depth"] = {"feature": "observation.depth.wrist", "scale_m": 0.001}
        # The intrinsics are the depth image's, not the 640x480 video's (intrinsics for another size are an error).
        del calib["video_key"]
    if timing is not None:
        calib["timing"] = timing
    (folder / "calib").mkdir(parents=True, exist_ok=True)
    (folder / "calib" / "wrist.yaml").write_text(yaml.safe_dump(calib))
    cfg: dict[str, Any] = {
        "urdf": str(ARM6),
        "state_feature": "observation.state",
        "world_frame": "world",
        "world_from_base": {"xyz": list(WORLD_FROM_BASE_XYZ), "rpy": [0.0, 0.0, WORLD_FROM_BASE_YAW]},
        "default_unit": "deg",
        "joints": {**{f"{j}.pos": j for j in ARM_JOINTS},
                   "gripper.pos": {"joint": "finger_left", "unit": "range_0_100"}},
        "cameras": {"wrist": "calib/wrist.yaml"},
    }
    if detections is not None:
        cfg["detections"] = detections
    if chain is not None:
        cfg["chain"] = chain
    path = folder / "robot.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def write_detection_table(
    path: Path, dataset: ArmDataset, episode: int, *, by: str = "frame_index", other_episode: int | None = None,
    frames: npt.ArrayLike | None = None,
) -> int:
    """A side table of the target's detections in ``episode`` (default every second frame); returns its rows."""
    import pyarrow as pa
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    t = dataset.timestamps[episode]
    frames = np.arange(0, t.size, 2) if frames is None else np.asarray(frames)
    t_cam = dataset.camera_times[episode] if dataset.camera_times else t + dataset.camera_delay_s
    u, v, z = project_truth(t_cam[frames])
    cols: dict[str, Any] = {
        "episode_index": np.full(frames.size, episode), "camera": ["wrist"] * frames.size,
        "u": u, "v": v, "depth_m": z, "label": ["cup"] * frames.size, "score": np.full(frames.size, 0.9),
    }
    if by == "frame_index":
        cols["frame_index"] = frames
    else:
        cols["timestamp"] = t_cam[frames]
    table = pa.table(cols)
    if other_episode is not None:  # rows of another episode that must be filtered out
        extra = table.slice(0, 3).set_column(0, "episode_index", pa.array(np.full(3, other_episode)))
        table = pa.concat_tables([table, extra])
    if path.suffix == ".csv":
        pacsv.write_csv(table, path)
    else:
        pq.write_table(table, path)
    return int(frames.size)
