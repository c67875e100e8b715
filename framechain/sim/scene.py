"""A scene generator with known faults: a mobile base with a mast camera looking at a static object.

The base orbits the object (up to about 1 m/s and 0.8 rad/s) while its heading wobbles, so the
object moves across the image and the robot's speed varies. It publishes what a real robot
records: ``/tf`` (map -> odom drifting slowly at 50 Hz, odom -> base_link at 100 Hz),
``/tf_static`` (the mast mount, pitched down, and the REP-103 optical rotation), CameraInfo,
depth (inline or as images) and detections at 30 Hz with pixel and depth noise, and the evidence
topics of the chosen evidence level.

Faults are injected either **in the robot's computation** (``where="robot"``: the recorded data is
right, the robot's logged points are wrong) or **in the recorded data** (``where="data"``: the data
is wrong, the robot was right). ``expected`` on the result says what attribution should find.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from scipy.spatial.transform import Rotation

from framechain.replay import TransformBuffer
from framechain.replay.buffer import invert
from framechain.replay.camera import CameraModel
from framechain.replay.catalogue import FAULT_HOPS, Fault
from framechain.replay.replay import compose_rows, transform_points
from framechain.timeline import (
    OPTICAL_FROM_LINK_QUAT_XYZW,
    CameraTable,
    ChainConfig,
    ChainEvidence,
    ChainFrames,
    ChainTopics,
    DepthFrameTable,
    FramechainError,
    HopTopics,
    ObservationTable,
    PointRole,
    PointTable,
    Timeline,
    TransformTable,
)
from framechain.timeline.arrays import FloatArray, IntArray

#: camera_link (FLU) -> optical frame (RDF), REP-103.
START_NS = 1_700_000_000_000_000_000
TOPICS = ChainTopics(
    camera_info="/camera/color/camera_info", detections="/detections", depth="/camera/depth/image_rect_raw"
)
HOP_TOPICS = HopTopics(camera="/debug/point_camera", body="/debug/point_body", world="/debug/point_world")
TARGET_TOPIC = "/grasp_target"
REFERENCE_TOPIC = "/mocap/target"

Evidence = Literal["hops", "target", "reference", "static"]
Where = Literal["robot", "data"]


class SceneError(FramechainError):
    """A scene that cannot be generated as asked (a fault where it cannot live)."""


@dataclass(frozen=True)
class InjectedFault:
    """One fault and where it lives. Parameters by kind:

    latency ``offset_s`` (robot: the pose used is the one at tau + offset; data: detections are
    stamped ``-offset_s`` late, so the pose that explains them is again at tau + offset);
    rotation_error ``angle_deg``, ``axis`` (body frame); missing_rotation (none: the mount's
    rotation is dropped, the optical rotation kept); axis_flip ``permutation`` (3x3 signed, applied
    to camera-frame points); depth_scale ``factor`` (as-run / true); intrinsics ``scale`` (as-run
    focal / true focal, K of another resolution); wrong_world_frame (odom used for map);
    inverted_transform ``hop`` (camera_to_body or body_to_world).
    """

    kind: Fault
    where: Where = "robot"
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def hop(self) -> str:
        if self.kind == Fault.INVERTED_TRANSFORM:
            return str(self.params.get("hop", "camera_to_body"))
        return FAULT_HOPS[self.kind].value




@dataclass(frozen=True)
class SceneSpec:
    """Everything that shapes a generated episode; equal specs give equal scenes."""

    seed: int = 0
    duration_s: float = 10.0
    camera_rate_hz: float = 30.0
    odom_rate_hz: float = 100.0
    drift_rate_hz: float = 50.0
    width: int = 640
    height: int = 480
    focal_px: float = 600.0
    mount_xyz: tuple[float, float, float] = (0.30, 0.0, 1.20)
    mount_pitch_deg: float = 30.0
    object_world: tuple[float, float, float] = (3.0, 1.0, 0.10)
    orbit_radius_m: float = 2.4
    orbit_rate: float | None = None  # rad/s; None: drawn from the seed
    wobble_rad: float | None = None
    pixel_noise_px: float = 0.5
    depth_noise_rel: float = 0.003
    reference_noise_m: float = 0.002
    evidence: Evidence = "hops"
    depth_images: bool = False
    faults: tuple[InjectedFault, ...] = ()


@dataclass(frozen=True)
class Scene:
    """A generated episode: the recorded timeline, its chain configuration and the truth."""

    spec: SceneSpec
    timeline: Timeline
    chain: ChainConfig
    object_world: FloatArray
    robot_world: FloatArray  # (N, 3) the world points the robot computed (acted on)

    @property
    def expected(self) -> list[tuple[str, str]]:
        """(fault, hop) pairs attribution should report, largest effect unknown in advance."""
        return [(f.kind.value, f.hop) for f in self.spec.faults]


def _identity3() -> FloatArray:
    return np.eye(3)


@dataclass(frozen=True)
class _ChainParams:
    """One version of the chain: the truth, what was recorded, or what the robot used."""

    K: FloatArray
    depth_factor: float = 1.0
    mount_quat: FloatArray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    optical_quat: FloatArray = field(default_factory=lambda: np.array(OPTICAL_FROM_LINK_QUAT_XYZW))
    cam_permutation: FloatArray = field(default_factory=_identity3)
    pose_offset_ns: int = 0
    world: str = "map"
    invert_camera: bool = False
    invert_pose: bool = False


def generate(spec: SceneSpec) -> Scene:
    """Generate one episode (deterministic in ``spec``)."""
    rng = np.random.default_rng(spec.seed)
    orbit_rate = spec.orbit_rate if spec.orbit_rate is not None else rng.uniform(0.15, 0.38) * rng.choice([-1, 1])
    wobble = spec.wobble_rad if spec.wobble_rad is not None else rng.uniform(0.08, 0.2)
    wobble_freq = rng.uniform(1.0, 2.2)
    radius_freq = rng.uniform(0.3, 0.8)
    phase0 = rng.uniform(-np.pi, np.pi)
    obj = np.asarray(spec.object_world, dtype=float)

    def base_pose(t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
        """T_map_base at times in seconds since the start: translation (N, 3), quat (N, 4)."""
        radius = spec.orbit_radius_m + 0.5 * np.sin(radius_freq * t_s)
        phi = phase0 + orbit_rate * t_s + 0.3 * np.sin(0.5 * t_s)
        pos = np.stack([obj[0] + radius * np.cos(phi), obj[1] + radius * np.sin(phi), np.zeros_like(t_s)], 1)
        heading = np.arctan2(obj[1] - pos[:, 1], obj[0] - pos[:, 0]) + wobble * np.sin(wobble_freq * t_s)
        return pos, Rotation.from_euler("z", heading[:, None]).as_quat()

    def drift(t_s: FloatArray) -> tuple[FloatArray, FloatArray]:
        """T_map_odom: linear in time (so tf2 interpolation between its samples is exact)."""
        trans = np.stack([0.20 + 0.010 * t_s, -0.10 + 0.006 * t_s, np.zeros_like(t_s)], 1)
        return trans, Rotation.from_euler("z", (0.02 + 0.002 * t_s)[:, None]).as_quat()

    # /tf: samples from 0.5 s before the first frame to 0.5 s after the last.
    t_odom = np.arange(-0.5, spec.duration_s + 0.5, 1.0 / spec.odom_rate_hz)
    t_drift = np.arange(-0.5, spec.duration_s + 0.5 + 1e-9, 1.0 / spec.drift_rate_hz)
    base_t, base_q = base_pose(t_odom)
    drift_t_at_odom, drift_q_at_odom = drift(t_odom)
    odom_t, odom_q = compose_rows(*_invert_rows(drift_t_at_odom, drift_q_at_odom), base_t, base_q)
    drift_t, drift_q = drift(t_drift)
    true_mount_q = Rotation.from_euler("y", spec.mount_pitch_deg, degrees=True).as_quat()
    K_true = np.array([[spec.focal_px, 0, spec.width / 2], [0, spec.focal_px, spec.height / 2], [0, 0, 1.0]])
    truth = _ChainParams(K=K_true, mount_quat=true_mount_q)
    recorded, robot = truth, truth
    for fault in spec.faults:
        if fault.where == "robot":
            robot = _inject(robot, fault, truth)
        else:
            recorded = _inject_data(recorded, fault, truth)

    dynamic = TransformTable.concat(
        [
            TransformTable.from_rows("map", "odom", ns(t_drift), drift_t, drift_q, source="/tf"),
            TransformTable.from_rows("odom", "base_link", ns(t_odom), odom_t, odom_q, source="/tf"),
        ]
    )

    def static_tf(params: _ChainParams) -> TransformTable:
        mount = TransformTable.from_rows(
            "base_link",
            "camera_link",
            [START_NS],
            [spec.mount_xyz],
            [params.mount_quat],
            is_static=True,
            source="/tf_static",
        )
        optical = TransformTable.from_rows(
            "camera_link",
            "camera_optical_frame",
            [START_NS],
            [[0.0, 0.0, 0.0]],
            [params.optical_quat],
            is_static=True,
            source="/tf_static",
        )
        if params.invert_camera:  # the mount published the wrong way round (still one parent per child)
            t_inv, q_inv = _invert_rows(np.array([spec.mount_xyz]), np.array([params.mount_quat]))
            mount = TransformTable.from_rows(
                "base_link", "camera_link", [START_NS], t_inv, q_inv, is_static=True, source="/tf_static"
            )
        return TransformTable.concat([mount, optical])

    true_tf = TransformTable.concat([dynamic, static_tf(truth)])
    recorded_tf = TransformTable.concat([dynamic, static_tf(recorded)])

    # Camera frames: capture times, the object's true pixel and depth, then noise.
    t_cam = np.arange(0.1, spec.duration_s - 0.1, 1.0 / spec.camera_rate_hz)
    capture_ns = ns(t_cam)
    true_buffer = TransformBuffer(true_tf)
    world_from_opt = true_buffer.lookup("map", "camera_optical_frame", capture_ns)
    opt_from_world_t, opt_from_world_q = _invert_rows(world_from_opt.translation, world_from_opt.quat_xyzw)
    p_opt = transform_points(opt_from_world_t, opt_from_world_q, np.tile(obj, (t_cam.size, 1)))
    cam_model = CameraModel("camera_optical_frame", K_true, spec.width, spec.height)
    u_true, v_true = cam_model.project(p_opt)
    u = u_true + rng.normal(0.0, spec.pixel_noise_px, t_cam.size)
    v = v_true + rng.normal(0.0, spec.pixel_noise_px, t_cam.size)
    depth_measured = np.round(p_opt[:, 2] * (1.0 + rng.normal(0.0, spec.depth_noise_rel, t_cam.size)), 3)
    visible = cam_model.inside(u, v) & (p_opt[:, 2] > 0.1)
    u, v, depth_measured, capture_ns = u[visible], v[visible], depth_measured[visible], capture_ns[visible]
    n = capture_ns.size

    # The recorded detection stamps (a late camera clock is a data latency fault).
    stamp_shift = -recorded.pose_offset_ns  # stamps late by -offset so the right pose is at tau + offset
    obs_stamp = capture_ns + stamp_shift
    log_delay = rng.integers(3_000_000, 12_000_000, n)
    recorded_depth = np.round(depth_measured * recorded.depth_factor, 3)
    observations = ObservationTable(
        obs_id=np.arange(n),
        stamp_ns=obs_stamp,
        log_time_ns=obs_stamp + log_delay,
        camera_frame=np.full(n, "camera_optical_frame"),
        u=u,
        v=v,
        depth_m=np.full(n, np.nan) if spec.depth_images else recorded_depth,
        label=np.full(n, "cup"),
        score=np.full(n, 0.9),
        source=np.full(n, TOPICS.detections or ""),
    )
    cameras = CameraTable(
        frame=np.full(n, "camera_optical_frame"),
        stamp_ns=obs_stamp,
        log_time_ns=obs_stamp + log_delay,
        width=np.full(n, spec.width),
        height=np.full(n, spec.height),
        K=np.tile(recorded.K, (n, 1, 1)),
        distortion_model=np.full(n, "plumb_bob"),
        distortion=np.zeros((n, 14)),
        n_distortion=np.full(n, 5),
        source=np.full(n, TOPICS.camera_info or ""),
    )
    depth_frames = DepthFrameTable.empty()
    if spec.depth_images:
        depth_frames = _render_depth(spec, truth.K, true_buffer, capture_ns, obs_stamp, u, v, recorded_depth)

    # The robot's own computation, from the same pixels and measured depth, with its parameters.
    robot_cam = _pixel_to_camera(robot.K, u, v, depth_measured * robot.depth_factor)
    robot_body = _camera_to_body(robot, spec.mount_xyz, robot_cam)
    pose = true_buffer.lookup(robot.world, "base_link", capture_ns + robot.pose_offset_ns)
    pose_t, pose_q = pose.translation, pose.quat_xyzw
    if robot.invert_pose:
        pose_t, pose_q = _invert_rows(pose_t, pose_q)
    robot_world = transform_points(pose_t, pose_q, robot_body)

    evidence, points = _evidence(spec, rng, obs_stamp, log_delay, robot_cam, robot_body, robot_world, obj)
    chain = ChainConfig(
        frames=ChainFrames(camera="camera_optical_frame", body="base_link", world="map"),
        topics=replace(TOPICS, depth=TOPICS.depth if spec.depth_images else None),
        evidence=evidence,
        latency_budget_s=0.02,
    )
    timeline = Timeline(
        transforms=recorded_tf,
        cameras=cameras,
        observations=observations,
        points=points,
        depth_frames=depth_frames,
        metadata={
            "source": {"path": "<generated>", "format": "generated"},
            "seed": spec.seed,
            "generator": "framechain.sim",
        },
    )
    return Scene(spec=spec, timeline=timeline, chain=chain, object_world=obj, robot_world=robot_world)


def _inject(params: _ChainParams, fault: InjectedFault, truth: _ChainParams) -> _ChainParams:
    p = fault.params
    kind = fault.kind
    if kind == Fault.LATENCY:
        return replace(params, pose_offset_ns=round(float(p["offset_s"]) * 1e9))
    if kind == Fault.ROTATION_ERROR:
        error = Rotation.from_rotvec(np.deg2rad(float(p["angle_deg"])) * _unit(p.get("axis", (0, 0, 1))))
        return replace(params, mount_quat=(error * Rotation.from_quat(truth.mount_quat)).as_quat())
    if kind == Fault.MISSING_ROTATION:
        return replace(params, mount_quat=np.array([0.0, 0.0, 0.0, 1.0]))
    if kind == Fault.AXIS_FLIP:
        return replace(params, cam_permutation=np.asarray(p["permutation"], dtype=float))
    if kind == Fault.DEPTH_SCALE:
        return replace(params, depth_factor=float(p["factor"]))
    if kind == Fault.INTRINSICS:
        k = truth.K.copy()
        k[:2, :] *= float(p["scale"])  # the K of another resolution: focal and principal point scale
        return replace(params, K=k)
    if kind == Fault.WRONG_WORLD_FRAME:
        return replace(params, world="odom")
    if kind == Fault.INVERTED_TRANSFORM:
        if fault.hop == "body_to_world":
            return replace(params, invert_pose=True)
        return replace(params, invert_camera=True)
    raise SceneError(f"unknown fault {kind}")


def _inject_data(params: _ChainParams, fault: InjectedFault, truth: _ChainParams) -> _ChainParams:
    """A fault in the recorded data: what the log says differs from what the robot used."""
    if fault.kind == Fault.AXIS_FLIP:
        # A recorded rotation can only permute axes properly (det +1): the optical edge published wrong.
        perm = np.asarray(fault.params["permutation"], dtype=float)
        if not np.isclose(np.linalg.det(perm), 1.0):
            raise SceneError("a recorded axis flip must be a proper rotation (det +1)")
        wrong = Rotation.from_quat(truth.optical_quat) * Rotation.from_matrix(perm)
        return replace(params, optical_quat=wrong.as_quat())
    if fault.kind == Fault.WRONG_WORLD_FRAME or (
        fault.kind == Fault.INVERTED_TRANSFORM and fault.hop == "body_to_world"
    ):
        raise SceneError(f"{fault.kind.value} at {fault.hop} is a fault of the robot's computation only; drop @data")
    return _inject(params, fault, truth)


def ns(t_s: FloatArray) -> IntArray:
    """Seconds since the episode start to absolute nanoseconds."""
    out: IntArray = START_NS + np.round(t_s * 1e9).astype(np.int64)
    return out


def _unit(axis: Sequence[float]) -> FloatArray:
    a = np.asarray(axis, dtype=float)
    out: FloatArray = a / np.linalg.norm(a)
    return out


def _invert_rows(t: FloatArray, q: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Row-wise inverse of (N, 3)/(N, 4) transforms (the replay's components-first inverse)."""
    t_inv, q_inv = invert(np.asarray(t, dtype=float).T, np.asarray(q, dtype=float).T)
    return t_inv.T, q_inv.T


def _pixel_to_camera(K: FloatArray, u: FloatArray, v: FloatArray, depth: FloatArray) -> FloatArray:
    x = (u - K[0, 2]) / K[0, 0]
    y = (v - K[1, 2]) / K[1, 1]
    return np.stack([x * depth, y * depth, depth], axis=1)


def _camera_to_body(params: _ChainParams, mount_xyz: Sequence[float], p_cam: FloatArray) -> FloatArray:
    """The robot's camera_to_body with its mount, optical rotation, axis permutation, inversion."""
    r_body_opt = Rotation.from_quat(params.mount_quat) * Rotation.from_quat(params.optical_quat)
    t = np.asarray(mount_xyz, dtype=float)
    p = p_cam @ params.cam_permutation.T
    out: FloatArray = r_body_opt.inv().apply(p - t) if params.invert_camera else r_body_opt.apply(p) + t
    return out


def _evidence(
    spec: SceneSpec,
    rng: np.random.Generator,
    stamps: IntArray,
    log_delay: IntArray,
    robot_cam: FloatArray,
    robot_body: FloatArray,
    robot_world: FloatArray,
    obj: FloatArray,
) -> tuple[ChainEvidence, PointTable]:
    n = stamps.size
    rows: list[PointTable] = []

    def table(frame: str, xyz: FloatArray, role: PointRole, topic: str) -> PointTable:
        return PointTable(
            frame=np.full(n, frame),
            stamp_ns=stamps,
            log_time_ns=stamps + log_delay + 1_000_000,
            xyz=xyz,
            quat_xyzw=np.full((n, 4), np.nan),
            role=np.full(n, role.value),
            obs_id=np.full(n, -1),
            source=np.full(n, topic),
        )

    if spec.evidence == "hops":
        rows += [
            table("camera_optical_frame", robot_cam, PointRole.HOP_CAMERA, HOP_TOPICS.camera or ""),
            table("base_link", robot_body, PointRole.HOP_BODY, HOP_TOPICS.body or ""),
            table("map", robot_world, PointRole.HOP_WORLD, HOP_TOPICS.world or ""),
        ]
        evidence = ChainEvidence(hops=HOP_TOPICS, static_target=True)
    elif spec.evidence == "target":
        rows.append(table("map", robot_world, PointRole.TARGET, TARGET_TOPIC))
        evidence = ChainEvidence(target=TARGET_TOPIC, static_target=True)
    elif spec.evidence == "reference":
        mocap = obj + rng.normal(0.0, spec.reference_noise_m, (n, 3))
        rows.append(table("map", mocap, PointRole.REFERENCE, REFERENCE_TOPIC))
        evidence = ChainEvidence(reference=REFERENCE_TOPIC, static_target=True)
    else:
        evidence = ChainEvidence(static_target=True)
    return evidence, PointTable.concat(rows)


def _render_depth(
    spec: SceneSpec,
    K: FloatArray,
    buffer: TransformBuffer,
    capture_ns: IntArray,
    stamps: IntArray,
    u: FloatArray,
    v: FloatArray,
    object_depth: FloatArray,
) -> DepthFrameTable:
    """Depth images registered to the colour camera: the floor plane plus a disc at the object.

    The disc carries the measured object depth so the replay's window median returns it exactly
    (to the millimetre); the floor comes from intersecting each pixel's ray with z = 0.
    """
    world_from_opt = buffer.lookup("map", "camera_optical_frame", capture_ns)
    cols, rows = np.meshgrid(np.arange(spec.width, dtype=float), np.arange(spec.height, dtype=float))
    rays = np.stack([(cols - K[0, 2]) / K[0, 0], (rows - K[1, 2]) / K[1, 1], np.ones_like(cols)], -1)
    rays = rays.reshape(-1, 3)
    images = np.zeros((capture_ns.size, spec.height, spec.width), dtype=np.float32)
    radius2 = 8.0**2
    for i in range(capture_ns.size):  # one image per frame: this loop is over frames, not messages per hop
        rot = Rotation.from_quat(world_from_opt.quat_xyzw[i])
        dirs_world = rot.apply(rays)
        origin_z = world_from_opt.translation[i, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(dirs_world[:, 2] < -1e-6, -origin_z / dirs_world[:, 2], 0.0)
        floor = np.where((z > 0) & (z < 20.0), z, 0.0).reshape(spec.height, spec.width)
        disc = (cols - u[i]) ** 2 + (rows - v[i]) ** 2 <= radius2
        floor[disc] = object_depth[i]
        images[i] = floor
    return DepthFrameTable.from_arrays("camera_optical_frame", stamps, images, source=TOPICS.depth or "")
