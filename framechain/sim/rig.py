"""Rigs of several cameras with known faults: a fixed arena, a moving rig with odometry, a moving rig with no pose.

- ``fixed``: cameras on the walls of an arena (body = world), static tags on the floor and a wand of
  tags carried through the middle (moving labels);
- ``moving``: a rig of cameras looking ahead, carried past a wall of static tags, its pose recorded as
  odometry (``world -> rig`` at 100 Hz); a wand moves in front of it;
- ``none``: the same rig and motion with no pose recorded (the chain has no world frame).

Every camera sees at its frame rate (hardware-synced by default); a detection is a pixel with depth
(noisy). Faults live in the recorded data: a camera's recorded mount turned by an angle about an axis
of its own frame, its detections stamped late by some frames, its recorded focal length or its depths
scaled. The truth is computed with the
generator's own maths (:mod:`framechain.sim.rigid`: numpy and scipy), never framechain's replay.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from framechain.arrays import FloatArray
from framechain.config.chain import ChainConfig, ChainEvidence, ChainFrames
from framechain.config.chain_cameras import RigCamera
from framechain.sim import rigid
from framechain.timeline import CameraTable, ObservationTable, Timeline, TransformTable

START_NS = 1_700_000_000_000_000_000
WIDTH, HEIGHT, FOCAL = 1280, 960, 700.0
ODOMETRY_HZ = 100.0

RigPoseKind = Literal["fixed", "moving", "none"]


@dataclass(frozen=True)
class RigSpec:
    """A generated rig and what is wrong in its recorded data."""

    pose: RigPoseKind = "fixed"
    cameras: int = 4
    rate_hz: float = 30.0
    duration_s: float = 20.0
    static_tags: int = 16
    wand_tags: int = 3
    pixel_noise: float = 0.3
    depth_noise_m: float = 0.01
    seed: int = 0
    #: the recorded mount of camera ``turned[0]`` turned by ``turned[1]`` degrees about axis ``turned[2]`` of
    #: the camera's own (optical) frame
    turned: tuple[int, float, tuple[float, float, float]] | None = None
    #: camera ``late[0]``'s detections stamped ``late[1]`` frames late
    late: tuple[int, float] | None = None
    #: camera ``focal[0]``'s recorded focal length ``focal[1]`` times the true one
    focal: tuple[int, float] | None = None
    #: camera ``depth[0]``'s recorded depths ``depth[1]`` times the true ones
    depth: tuple[int, float] | None = None


@dataclass(frozen=True)
class RigScene:
    """A generated rig: the timeline as recorded, its chain, and the truth."""

    spec: RigSpec
    timeline: Timeline
    chain: ChainConfig
    #: T_body_cam of every camera, as it really is (4x4)
    true_mounts: dict[str, FloatArray] = field(default_factory=dict)
    #: T_body_cam as recorded in the log (4x4)
    recorded_mounts: dict[str, FloatArray] = field(default_factory=dict)

    def frame(self, camera: int) -> str:
        return self.chain.cameras[camera].frame


def generate_rig(spec: RigSpec) -> RigScene:
    """The rig of ``spec`` with its faults in the recorded data (see the module docstring)."""
    rng = np.random.default_rng(spec.seed)
    frames = [f"cam{k}_optical_frame" for k in range(spec.cameras)]
    body = "arena" if spec.pose == "fixed" else "rig"
    world = "arena" if spec.pose == "fixed" else "world"
    mounts = _fixed_mounts(spec.cameras) if spec.pose == "fixed" else _rig_mounts(spec.cameras)
    recorded = dict(zip(frames, mounts, strict=True))
    if spec.turned is not None:
        k, angle, axis = spec.turned
        turn = np.eye(4)
        turn[:3, :3] = Rotation.from_rotvec(np.deg2rad(angle) * np.asarray(axis) / np.linalg.norm(axis)).as_matrix()
        recorded[frames[k]] = mounts[k] @ turn
    period = 1.0 / spec.rate_hz
    times_s = np.arange(0.0, spec.duration_s, period)
    world_from_body = _body_path(spec, times_s)
    tags = _static_tags(spec, rng)
    rows: list[tuple[np.ndarray, ...]] = []
    for k, frame in enumerate(frames):
        late = spec.late[1] * period if spec.late is not None and spec.late[0] == k else 0.0
        seen = _sightings(spec, rng, k, frame, mounts[k], times_s, world_from_body, tags, late)
        if spec.depth is not None and spec.depth[0] == k:
            seen = (*seen[:4], seen[4] * spec.depth[1], *seen[5:])
        rows.append(seen)
    observations = _observation_table(rows)
    transforms = _transforms(spec, frames, recorded, body, world)
    focal = [FOCAL * (spec.focal[1] if spec.focal is not None and spec.focal[0] == k else 1.0)
             for k in range(len(frames))]
    cameras = CameraTable.concat([CameraTable.from_intrinsics(f, fx=fk, fy=fk, cx=WIDTH / 2 - 0.5,
                                                              cy=HEIGHT / 2 - 0.5, width=WIDTH, height=HEIGHT,
                                                              source=f"/{f.removesuffix('_optical_frame')}/info")
                                  for f, fk in zip(frames, focal, strict=True)])
    chain = ChainConfig(
        frames=ChainFrames(camera=frames[0], body=body, world=world if spec.pose != "none" else body),
        cameras=tuple(RigCamera(frame=f, detections=f"/{f.removesuffix('_optical_frame')}/tags") for f in frames),
        evidence=ChainEvidence(static_target=True, moving_labels=tuple(f"wand{i}" for i in range(spec.wand_tags))),
        has_pose=spec.pose != "none",
    )
    timeline = Timeline(transforms=transforms, cameras=cameras, observations=observations,
                        metadata={"source": {"path": f"rig-{spec.pose}", "format": "generated"}})
    return RigScene(spec, timeline, chain, dict(zip(frames, mounts, strict=True)), recorded)


def _look_at(eye: FloatArray, target: FloatArray) -> FloatArray:
    """T_body_cam (4x4) of an optical frame at ``eye`` looking at ``target`` (z forward, y down, x right)."""
    z = target - eye
    z = z / np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    out = np.eye(4)
    out[:3, :3] = np.stack([x, y, z], axis=1)
    out[:3, 3] = eye
    return out


def _fixed_mounts(n: int) -> list[FloatArray]:
    """Cameras on the walls of an 8 x 6 m arena at 2.5 m, looking at its middle."""
    angles = np.linspace(0.0, 2 * np.pi, n, endpoint=False) + 0.3
    return [_look_at(np.array([4.0 * np.cos(a), 3.0 * np.sin(a), 2.5]), np.array([0.0, 0.0, 0.5])) for a in angles]


def _rig_mounts(n: int) -> list[FloatArray]:
    """Cameras on a rig 10 cm apart, looking ahead (+x) with their headings fanned out by 15 degrees."""
    out = []
    for k in range(n):
        offset = (k - (n - 1) / 2)
        eye = np.array([0.1, 0.1 * offset, 0.05 * (k % 2)])
        heading = np.deg2rad(15.0 * offset)
        out.append(_look_at(eye, eye + np.array([np.cos(heading), np.sin(heading), -0.05])))
    return out


def _body_path(spec: RigSpec, times_s: FloatArray) -> FloatArray:
    """T_world_body (T, 4, 4) at the frame times: still for a fixed rig, a walk past the tag wall otherwise."""
    out = np.tile(np.eye(4), (times_s.size, 1, 1))
    if spec.pose == "fixed":
        return out
    yaw = 0.25 * np.sin(2 * np.pi * times_s / 7.0)
    out[:, :3, :3] = Rotation.from_euler("z", yaw[:, None]).as_matrix()
    out[:, 0, 3] = 0.6 * np.sin(2 * np.pi * times_s / 11.0)
    out[:, 1, 3] = 1.5 * np.sin(2 * np.pi * times_s / 9.0)
    out[:, 2, 3] = 0.05 * np.sin(2 * np.pi * times_s / 3.0)
    return out


def _static_tags(spec: RigSpec, rng: np.random.Generator) -> FloatArray:
    """Static tags: on the arena's floor and low boxes, or on a wall 3 m ahead of the rig."""
    if spec.pose == "fixed":
        return np.column_stack([rng.uniform(-2.0, 2.0, spec.static_tags), rng.uniform(-1.5, 1.5, spec.static_tags),
                                rng.uniform(0.0, 1.2, spec.static_tags)])
    return np.column_stack([np.full(spec.static_tags, 3.0) + rng.uniform(-0.2, 0.2, spec.static_tags),
                            rng.uniform(-2.5, 2.5, spec.static_tags), rng.uniform(-0.6, 0.6, spec.static_tags)])


def _wand(spec: RigSpec, times_s: FloatArray) -> FloatArray:
    """(T, W, 3) world points of the wand's tags: a bar swung through the middle (or in front of the rig)."""
    centre = np.column_stack([1.2 * np.sin(2 * np.pi * times_s / 6.0), 0.9 * np.sin(2 * np.pi * times_s / 4.0),
                              1.0 + 0.3 * np.sin(2 * np.pi * times_s / 5.0)])
    if spec.pose != "fixed":
        centre = centre * [0.3, 0.8, 0.3] + [1.8, 0.0, -0.7]
    along = np.column_stack([np.cos(times_s), np.sin(times_s), np.zeros_like(times_s)])
    spacing = (np.arange(spec.wand_tags) - (spec.wand_tags - 1) / 2) * 0.15
    out: FloatArray = centre[:, None, :] + spacing[None, :, None] * along[:, None, :]
    return out


def _sightings(spec: RigSpec, rng: np.random.Generator, k: int, frame: str, mount: FloatArray, times_s: FloatArray,
               world_from_body: FloatArray, tags: FloatArray, late_s: float) -> tuple[np.ndarray, ...]:
    """One camera's detections: every tag in view at every frame, projected with noise, stamped (late by
    ``late_s``)."""
    cam_from_world = rigid.inverse(world_from_body @ mount)  # (T, 4, 4)
    wand = _wand(spec, times_s)
    labels = [f"tag{i}" for i in range(tags.shape[0])] + [f"wand{i}" for i in range(spec.wand_tags)]
    points = np.concatenate([np.broadcast_to(tags, (times_s.size, *tags.shape)), wand], axis=1)  # (T, L, 3)
    p_cam = np.einsum("tij,tlj->tli", cam_from_world[:, :3, :3], points) + cam_from_world[:, None, :3, 3]
    K = rigid.intrinsic_matrix(FOCAL, FOCAL, WIDTH / 2 - 0.5, HEIGHT / 2 - 0.5)
    flat = p_cam.reshape(-1, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        u, v = rigid.project(K, flat)
    seen = (flat[:, 2] > 0.3) & (flat[:, 2] < 9.0) & (u > 5) & (u < WIDTH - 5) & (v > 5) & (v < HEIGHT - 5)
    t_index, label_index = np.divmod(np.flatnonzero(seen), len(labels))
    n = int(seen.sum())
    stamp = START_NS + np.round((times_s[t_index] + late_s) * 1e9).astype(np.int64)
    return (stamp, np.full(n, frame), u[seen] + rng.normal(0.0, spec.pixel_noise, n),
            v[seen] + rng.normal(0.0, spec.pixel_noise, n),
            flat[seen, 2] + rng.normal(0.0, spec.depth_noise_m, n), np.asarray(labels)[label_index],
            np.full(n, f"/{frame.removesuffix('_optical_frame')}/tags"))


def _observation_table(rows: list[tuple[np.ndarray, ...]]) -> ObservationTable:
    stamp, frame, u, v, depth, label, source = (np.concatenate(c) for c in zip(*rows, strict=True))
    order = np.argsort(stamp, kind="stable")
    n = order.size
    return ObservationTable(obs_id=np.arange(n, dtype=np.int64), stamp_ns=stamp[order], log_time_ns=stamp[order],
                            camera_frame=frame[order], u=u[order], v=v[order], depth_m=depth[order],
                            label=label[order], score=np.ones(n), source=source[order])


def _transforms(spec: RigSpec, frames: list[str], recorded: dict[str, FloatArray], body: str,
                world: str) -> TransformTable:
    """The recorded mounts (static) and, for a moving rig with a pose, its odometry at 100 Hz."""
    t, q = rigid.to_rows(np.stack([recorded[f] for f in frames]))
    n = len(frames)
    tables = [TransformTable.from_rows(np.full(n, body), frames, np.full(n, START_NS), t, q, log_time_ns=np.full(
        n, START_NS), is_static=True, source="/tf_static")]
    if spec.pose == "moving":
        times = np.arange(-0.5, spec.duration_s + 0.5 + spec.rate_hz ** -1, 1.0 / ODOMETRY_HZ)
        tw, qw = rigid.to_rows(_body_path(spec, times))
        stamps = START_NS + np.round(times * 1e9).astype(np.int64)
        tables.append(TransformTable.from_rows(world, body, stamps, tw, qw, log_time_ns=stamps, source="/odom"))
    return TransformTable.concat(tables)


__all__ = ["RigScene", "RigSpec", "generate_rig"]
