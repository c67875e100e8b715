"""A scene generator with known faults: a mobile base with a mast camera looking at a static object.

The base orbits the object (up to about 1 m/s and 0.8 rad/s) while its heading wobbles, so the
object moves across the image and the robot's speed varies. It publishes what a real robot
records: ``/tf`` (map -> odom drifting slowly at 50 Hz, odom -> base_link at 100 Hz),
``/tf_static`` (base_link -> camera_link, the mast mount pitched down; camera_link -> the optical
frame, the REP-103 rotation plus an optional offset such as a RealSense colour imager's 15 mm),
CameraInfo, depth (inline or as images) and detections at 30 Hz with pixel and depth noise, and
the evidence topics of the chosen evidence level.

Faults are injected either **in the robot's computation** (``where="robot"``: the recorded data is
right, the robot's logged points are wrong) or **in the recorded data** (``where="data"``: the data
is wrong, the robot was right). ``expected`` and ``expected_findings`` on the result say what
attribution should find.

Every transform, projection and interpolation here is the generator's own
(:mod:`framechain.sim.rigid`: numpy and scipy only), never framechain's replay, so a bug in the
replay cannot cancel out of the benchmark built on these scenes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from scipy.spatial.transform import Rotation

from framechain.arrays import FloatArray, IntArray
from framechain.catalogue import FAULT_HOPS, Fault
from framechain.config.chain import ChainConfig, ChainEvidence, ChainFrames, ChainTopics, HopTopics
from framechain.errors import FramechainError
from framechain.geometry.conventions import OPTICAL_FROM_LINK_QUAT_XYZW
from framechain.sim import rigid
from framechain.sim.render import render_color, render_depth
from framechain.timeline import (
    CameraTable,
    DepthFrameTable,
    ImageFrameTable,
    ObservationTable,
    PointRole,
    PointTable,
    Timeline,
    TransformTable,
)

START_NS = 1_700_000_000_000_000_000
TOPICS = ChainTopics(
    camera_info="/camera/color/camera_info", detections="/detections", depth="/camera/depth/image_rect_raw"
)
HOP_TOPICS = HopTopics(camera="/debug/point_camera", body="/debug/point_body", world="/debug/point_world")
TARGET_TOPIC = "/grasp_target"
COLOR_TOPIC = "/camera/color/image_raw"
REFERENCE_TOPIC = "/mocap/target"
MOUNT_FRAME = "camera_link"
BODY_FRAME = "base_link"
FOOTPRINT_FRAME = "base_footprint"
#: A sibling imager's optical frame at camera_link's origin (a RealSense's depth camera).
DEPTH_OPTICAL_FRAME = "camera_depth_optical_frame"
#: A RealSense's colour optical frame: its name and its offset from camera_link (metres, camera_link axes).
REALSENSE_OPTICAL_FRAME = "camera_color_optical_frame"
REALSENSE_OPTICAL_XYZ = (0.0, 0.015, 0.0)

Evidence = Literal["hops", "target", "reference", "static"]
Where = Literal["robot", "data"]


class SceneError(FramechainError):
    """A scene that cannot be generated as asked (a fault where it cannot live)."""


@dataclass(frozen=True)
class InjectedFault:
    """One fault and where it lives. Parameters by kind:

    - latency ``offset_s`` (robot: the pose used is the one at tau + offset; data: detections are
      stamped ``-offset_s`` late, so the pose that explains them is again at tau + offset); or
      ``hold_s`` (robot only, a stale pose held: the robot used the pose at the latest odom sample
      at or before tau - hold_s instead of interpolating at tau; attribution should report an
      offset of about ``-(hold_s + half an odom period)``).
    - rotation_error ``angle_deg``, ``axis`` (body frame).
    - translation_error ``offset_m`` (x, y, z in base_link): the mount's position moved by it (robot: the robot
      used it; data: /tf_static publishes it). Attribution should report ``offset_m`` itself either way.
    - missing_rotation (no parameters: the mount's rotation is dropped, the optical rotation kept).
    - axis_flip ``permutation`` (3x3 signed, applied to camera-frame points; in the data a proper
      rotation published on the optical edge); or ``used="camera_link"``, the real form: in the
      robot, it looked up camera_link instead of the optical frame, so the optical points went
      through T_base_camera_link alone, losing the optical edge's REP-103 rotation AND its
      translation; in the data, the detections and their CameraInfo name camera_link (a driver
      configured with the link as its frame_id) while their pixels are optical. Attribution should
      report ``used == "camera_link"`` either way.
    - wrong_camera_frame ``used`` (robot only, default ``"camera_depth_optical_frame"``): the robot
      looked up the depth imager's optical frame (published at camera_link's origin with the
      REP-103 rotation) for colour detections: a translation of ``-optical_xyz`` alone, so the
      scene's ``optical_xyz`` must not be zero.
    - depth_scale ``factor`` (as-run / true).
    - intrinsics ``scale`` (as-run K / true K: ``scale=2`` is the camera_info of a 1280x960
      calibration used for 640x480 images, fx, fy, cx, cy all doubled; with ``variant="focal"`` the
      focal length alone, another lens).
    - wrong_world_frame ``used`` (robot only): ``"odom"`` (the default, odom used for map) or
      ``"base_footprint"`` (the robot looked up base_footprint instead of base_link: the scene
      then publishes base_link -> base_footprint, ``footprint_height_m`` (default 0.08) below).
    - inverted_transform ``hop`` (camera_to_body, or body_to_world for the robot only); in the data,
      the mount published inverted (T_camera_link_base on the base_link -> camera_link edge).
    """

    kind: Fault
    where: Where = "robot"
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def hop(self) -> str:
        if self.kind == Fault.INVERTED_TRANSFORM:
            return str(self.params.get("hop", "camera_to_body"))
        return FAULT_HOPS[self.kind].value

    @property
    def used_frame(self) -> str | None:
        """The frame the robot looked up instead of the right one, for the frame-swap forms."""
        if self.kind == Fault.WRONG_WORLD_FRAME:
            return str(self.params.get("used", "odom"))
        if self.kind == Fault.AXIS_FLIP and "used" in self.params:
            return str(self.params["used"])
        if self.kind == Fault.WRONG_CAMERA_FRAME:
            return str(self.params.get("used", DEPTH_OPTICAL_FRAME))
        return None


@dataclass(frozen=True)
class ExpectedFinding:
    """What attribution should report for one injected fault.

    ``estimate`` holds attribution.json estimate keys and their true values; ``tolerance`` the
    allowed absolute error of each numeric key (strings and lists must match exactly).
    """

    fault: str
    hop: str
    estimate: dict[str, Any]
    tolerance: dict[str, float]

    def names(self, fault: str, hop: str, estimate: Mapping[str, Any]) -> bool:
        """Whether a finding names this fault: the fault, the hop and, for frame swaps, the frame used."""
        if (fault, hop) != (self.fault, self.hop):
            return False
        return "used" not in self.estimate or estimate.get("used") == self.estimate["used"]

    def estimate_within(self, estimate: Mapping[str, Any]) -> bool:
        """Whether every expected estimate key is present and within its tolerance."""
        for key, want in self.estimate.items():
            got = estimate.get(key)
            if got is None:
                return False
            if isinstance(want, float):
                if not abs(float(got) - want) <= self.tolerance[key]:
                    return False
            elif _plain(got) != _plain(want):
                return False
        return True


def _plain(value: Any) -> Any:
    """Tuples and arrays as nested lists, so that [[1, 0], ...] equals ((1, 0), ...)."""
    if isinstance(value, tuple | list | np.ndarray):
        return [_plain(v) for v in value]
    return value


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
    optical_frame: str = "camera_optical_frame"
    optical_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)  # camera_link -> optical offset
    object_world: tuple[float, float, float] = (3.0, 1.0, 0.10)
    orbit_radius_m: float = 2.4
    orbit_rate: float | None = None  # rad/s; None: drawn from the seed
    wobble_rad: float | None = None
    #: the base stays where the orbit starts (a fixed camera over a static target: no motion to show
    #: a latency, and nothing to tell a mount rotation or a scale from the target's position)
    fixed_camera: bool = False
    pixel_noise_px: float = 0.5
    depth_noise_rel: float = 0.003
    reference_noise_m: float = 0.002
    evidence: Evidence = "hops"
    depth_images: bool = False
    #: JPEG colour images on ``/camera/color/image_raw`` (the floor and the object), one per detection.
    color_images: bool = False
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

    @property
    def expected_findings(self) -> list[ExpectedFinding]:
        """One expected finding per injected fault, with the estimate it should carry."""
        return [_expected_finding(self.spec, f) for f in self.spec.faults]


def _expected_finding(spec: SceneSpec, fault: InjectedFault) -> ExpectedFinding:
    p = fault.params
    estimate: dict[str, Any] = {}
    tolerance: dict[str, float] = {}
    if fault.kind == Fault.LATENCY:
        if "hold_s" in p:
            # The held sample is between hold_s and hold_s + one odom period old: on average half a period more.
            period = 1.0 / spec.odom_rate_hz
            estimate["offset_s"] = -(float(p["hold_s"]) + 0.5 * period)
            tolerance["offset_s"] = 0.5 * period + 0.002
        else:
            estimate["offset_s"], tolerance["offset_s"] = float(p["offset_s"]), 0.002
    elif fault.kind == Fault.ROTATION_ERROR:
        estimate["angle_deg"], tolerance["angle_deg"] = float(p["angle_deg"]), 0.5
    elif fault.kind == Fault.TRANSLATION_ERROR:
        estimate["distance_m"], tolerance["distance_m"] = float(np.linalg.norm(p["offset_m"])), 0.005
    elif fault.kind == Fault.MISSING_ROTATION:
        estimate["angle_deg"], tolerance["angle_deg"] = float(abs(spec.mount_pitch_deg)), 0.5
    elif fault.kind == Fault.DEPTH_SCALE:
        estimate["factor"] = float(p["factor"])
        tolerance["factor"] = 0.01 * abs(estimate["factor"])
    elif fault.kind == Fault.INTRINSICS:
        estimate["scale"] = float(p["scale"])
        tolerance["scale"] = 0.01 * abs(estimate["scale"])
    elif fault.kind == Fault.AXIS_FLIP:
        if fault.used_frame is not None:
            estimate["used"] = fault.used_frame
        else:
            estimate["permutation"] = np.asarray(p["permutation"], dtype=int).tolist()
    elif fault.kind in (Fault.WRONG_WORLD_FRAME, Fault.WRONG_CAMERA_FRAME):
        estimate["used"] = fault.used_frame
    elif fault.kind == Fault.INVERTED_TRANSFORM and fault.where == "data":
        estimate["edge"] = [BODY_FRAME, MOUNT_FRAME]
    return ExpectedFinding(fault.kind.value, fault.hop, estimate, tolerance)


@dataclass(frozen=True)
class _ChainParams:
    """One version of the chain: the truth, what was recorded, or what the robot used."""

    K: FloatArray
    depth_factor: float = 1.0
    mount_quat: FloatArray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    mount_offset: FloatArray = field(default_factory=lambda: np.zeros(3))  # added to the mount's position (m)
    optical_quat: FloatArray = field(default_factory=lambda: np.array(OPTICAL_FROM_LINK_QUAT_XYZW))
    cam_permutation: FloatArray = field(default_factory=lambda: np.eye(3))
    skip_optical_edge: bool = False  # camera_link looked up for optical points
    #: the frame the detections and CameraInfo name (None: the optical frame they are really in)
    detections_frame: str | None = None
    sibling_optical: bool = False  # the depth imager's optical frame looked up for colour points
    pose_offset_ns: int = 0
    hold_ns: int | None = None  # zero-order hold of the odom sample at or before tau - hold
    world: str = "map"
    body: str = BODY_FRAME
    invert_camera: bool = False
    invert_pose: bool = False


class _Motion:
    """The recorded /tf samples and tf-style lookups on them (the generator's own interpolation)."""

    def __init__(self, spec: SceneSpec, rng: np.random.Generator, obj: FloatArray) -> None:
        orbit_rate = spec.orbit_rate if spec.orbit_rate is not None else rng.uniform(0.15, 0.38) * rng.choice([-1, 1])
        wobble = spec.wobble_rad if spec.wobble_rad is not None else rng.uniform(0.08, 0.2)
        wobble_freq = rng.uniform(1.0, 2.2)
        radius_freq = rng.uniform(0.3, 0.8)
        phase0 = rng.uniform(-np.pi, np.pi)

        def map_from_base(t_s: FloatArray) -> FloatArray:
            if spec.fixed_camera:
                t_s = np.zeros_like(t_s)
            radius = spec.orbit_radius_m + 0.5 * np.sin(radius_freq * t_s)
            phi = phase0 + orbit_rate * t_s + 0.3 * np.sin(0.5 * t_s)
            pos = np.stack([obj[0] + radius * np.cos(phi), obj[1] + radius * np.sin(phi), np.zeros_like(t_s)], 1)
            heading = np.arctan2(obj[1] - pos[:, 1], obj[0] - pos[:, 0]) + wobble * np.sin(wobble_freq * t_s)
            return rigid.matrices(pos, Rotation.from_euler("z", heading[:, None]).as_quat())

        def map_from_odom(t_s: FloatArray) -> FloatArray:
            # Linear in time, so interpolating between its samples is exact.
            trans = np.stack([0.20 + 0.010 * t_s, -0.10 + 0.006 * t_s, np.zeros_like(t_s)], 1)
            return rigid.matrices(trans, Rotation.from_euler("z", (0.02 + 0.002 * t_s)[:, None]).as_quat())

        # Samples from 0.5 s before the first frame to 0.5 s after the last.
        t_odom = np.arange(-0.5, spec.duration_s + 0.5, 1.0 / spec.odom_rate_hz)
        t_drift = np.arange(-0.5, spec.duration_s + 0.5 + 1e-9, 1.0 / spec.drift_rate_hz)
        self.odom_ns = ns(t_odom)
        self.drift_ns = ns(t_drift)
        odom_from_base = rigid.inverse(map_from_odom(t_odom)) @ map_from_base(t_odom)
        self.odom_t, self.odom_q = rigid.to_rows(odom_from_base)
        self.drift_t, self.drift_q = rigid.to_rows(map_from_odom(t_drift))

    def table(self) -> TransformTable:
        return TransformTable.concat(
            [
                TransformTable.from_rows("map", "odom", self.drift_ns, self.drift_t, self.drift_q, source="/tf"),
                TransformTable.from_rows("odom", BODY_FRAME, self.odom_ns, self.odom_t, self.odom_q, source="/tf"),
            ]
        )

    def world_from_base(self, world: str, stamp_ns: IntArray) -> FloatArray:
        """``T_world_base_link`` at ``stamp_ns``: each dynamic edge interpolated on its own, as tf2 does."""
        odom_from_base = rigid.interpolate(self.odom_ns, self.odom_t, self.odom_q, stamp_ns)
        if world == "odom":
            return odom_from_base
        out: FloatArray = rigid.interpolate(self.drift_ns, self.drift_t, self.drift_q, stamp_ns) @ odom_from_base
        return out


def generate(spec: SceneSpec) -> Scene:
    """Generate one episode (deterministic in ``spec``)."""
    rng = np.random.default_rng(spec.seed)
    obj = np.asarray(spec.object_world, dtype=float)
    motion = _Motion(spec, rng, obj)
    true_mount_q = Rotation.from_euler("y", spec.mount_pitch_deg, degrees=True).as_quat()
    K_true = rigid.intrinsic_matrix(spec.focal_px, spec.focal_px, spec.width / 2, spec.height / 2)
    truth = _ChainParams(K=K_true, mount_quat=true_mount_q)
    recorded, robot = _faulty_params(spec, truth)
    footprint_height = [float(f.params.get("footprint_height_m", 0.08)) for f in spec.faults
                        if f.used_frame == FOOTPRINT_FRAME]
    body_from_footprint = rigid.matrix([0.0, 0.0, -footprint_height[0] if footprint_height else 0.0], [0, 0, 0, 1.0])
    footprint = body_from_footprint if footprint_height else None
    recorded_tf = TransformTable.concat([motion.table(), _static_tf(spec, recorded, footprint)])
    seen = _capture(spec, rng, motion, truth, obj)
    observations, cameras, obs_stamp, log_delay = _recorded_detections(spec, rng, recorded, seen)
    image_frames = ImageFrameTable.empty()
    if spec.color_images:
        image_frames = render_color(spec.width, spec.height, spec.optical_frame, COLOR_TOPIC, K_true,
                                    seen.world_from_optical, obs_stamp, seen.u, seen.v)
    depth_frames = DepthFrameTable.empty()
    if spec.depth_images:
        recorded_depth = np.round(seen.depth_m * recorded.depth_factor, 3)
        depth_frames = render_depth(spec.width, spec.height, spec.optical_frame, TOPICS.depth or "", K_true,
                                    seen.world_from_optical, obs_stamp, seen.u, seen.v, recorded_depth)
    robot_cam, robot_body, robot_world = _robot_points(spec, robot, motion, seen, body_from_footprint)
    evidence, points = _evidence(spec, rng, obs_stamp, log_delay, robot_cam, robot_body, robot_world, obj)
    chain = ChainConfig(
        frames=ChainFrames(camera=recorded.detections_frame or spec.optical_frame, body=BODY_FRAME, world="map"),
        topics=replace(TOPICS, depth=TOPICS.depth if spec.depth_images else None,
                       image=COLOR_TOPIC if spec.color_images else None),
        evidence=evidence,
        latency_budget_s=0.02,
    )
    timeline = Timeline(
        transforms=recorded_tf,
        cameras=cameras,
        observations=observations,
        points=points,
        depth_frames=depth_frames,
        image_frames=image_frames,
        metadata={
            "source": {"path": "<generated>", "format": "generated"},
            "seed": spec.seed,
            "generator": "framechain.sim",
        },
    )
    return Scene(spec=spec, timeline=timeline, chain=chain, object_world=obj, robot_world=robot_world)


def _faulty_params(spec: SceneSpec, truth: _ChainParams) -> tuple[_ChainParams, _ChainParams]:
    """The chain as recorded in the data and as the robot used it: the truth with the faults injected."""
    recorded, robot = truth, truth
    if any(f.used_frame == DEPTH_OPTICAL_FRAME for f in spec.faults) and not np.any(spec.optical_xyz):
        raise SceneError("wrong_camera_frame needs the colour optical frame off camera_link (optical_xyz not zero)")
    for fault in spec.faults:
        if fault.where == "robot":
            robot = _inject(robot, fault, truth)
        else:
            recorded = _inject_data(recorded, fault, truth)
    return recorded, robot


def _static_tf(spec: SceneSpec, params: _ChainParams, body_from_footprint: FloatArray | None) -> TransformTable:
    """The recorded /tf_static: the mount, the optical edge, and the frames the faults need."""
    mount_t, mount_q = np.array([spec.mount_xyz], dtype=float) + params.mount_offset, np.array([params.mount_quat])
    if params.invert_camera:  # the mount published the wrong way round (still one parent per child)
        mount_t, mount_q = rigid.to_rows(rigid.inverse(rigid.matrices(mount_t, mount_q)))
    tables = [
        TransformTable.from_rows(BODY_FRAME, MOUNT_FRAME, [START_NS], mount_t, mount_q,
                                 is_static=True, source="/tf_static"),
        TransformTable.from_rows(MOUNT_FRAME, spec.optical_frame, [START_NS], [spec.optical_xyz],
                                 [params.optical_quat], is_static=True, source="/tf_static"),
    ]
    if any(f.used_frame == DEPTH_OPTICAL_FRAME for f in spec.faults):
        tables.append(TransformTable.from_rows(MOUNT_FRAME, DEPTH_OPTICAL_FRAME, [START_NS], [[0.0, 0.0, 0.0]],
                                               [OPTICAL_FROM_LINK_QUAT_XYZW], is_static=True, source="/tf_static"))
    if body_from_footprint is not None:
        t, q = rigid.to_rows(body_from_footprint[None])
        tables.append(TransformTable.from_rows(BODY_FRAME, FOOTPRINT_FRAME, [START_NS], t, q,
                                               is_static=True, source="/tf_static"))
    return TransformTable.concat(tables)


@dataclass(frozen=True)
class _Seen:
    """The frames in which the camera saw the object: capture times, pixels and depth (noisy)."""

    capture_ns: IntArray
    u: FloatArray
    v: FloatArray
    depth_m: FloatArray  # measured (noise, millimetre rounding), before any depth fault
    world_from_optical: FloatArray  # (n, 4, 4) the true camera pose


def _capture(spec: SceneSpec, rng: np.random.Generator, motion: _Motion, truth: _ChainParams, obj: FloatArray
             ) -> _Seen:
    """Camera frames: capture times, the object's true pixel and depth, then noise; the visible ones."""
    t_cam = np.arange(0.1, spec.duration_s - 0.1, 1.0 / spec.camera_rate_hz)
    capture_ns = ns(t_cam)
    world_from_optical = motion.world_from_base("map", capture_ns) @ _base_from_camera(spec, truth)
    p_opt = rigid.apply(rigid.inverse(world_from_optical), np.tile(obj, (t_cam.size, 1)))
    u_true, v_true = rigid.project(truth.K, p_opt)
    u = u_true + rng.normal(0.0, spec.pixel_noise_px, t_cam.size)
    v = v_true + rng.normal(0.0, spec.pixel_noise_px, t_cam.size)
    depth_measured = np.round(p_opt[:, 2] * (1.0 + rng.normal(0.0, spec.depth_noise_rel, t_cam.size)), 3)
    # Pixel centres at integers: the image spans -0.5 .. size - 0.5 (what the replay accepts).
    inside = (u >= -0.5) & (u < spec.width - 0.5) & (v >= -0.5) & (v < spec.height - 0.5)
    visible = inside & (p_opt[:, 2] > 0.1)
    return _Seen(capture_ns[visible], u[visible], v[visible], depth_measured[visible], world_from_optical[visible])


def _recorded_detections(spec: SceneSpec, rng: np.random.Generator, recorded: _ChainParams, seen: _Seen
                         ) -> tuple[ObservationTable, CameraTable, IntArray, IntArray]:
    """The detections and CameraInfo as logged (a late camera clock is a data latency fault), with their
    header stamps and log delays."""
    n = seen.capture_ns.size
    detections_frame = recorded.detections_frame or spec.optical_frame
    stamp_shift = -recorded.pose_offset_ns  # stamps late by -offset so the right pose is at tau + offset
    obs_stamp = seen.capture_ns + stamp_shift
    log_delay = rng.integers(3_000_000, 12_000_000, n)
    recorded_depth = np.round(seen.depth_m * recorded.depth_factor, 3)
    observations = ObservationTable(
        obs_id=np.arange(n),
        stamp_ns=obs_stamp,
        log_time_ns=obs_stamp + log_delay,
        camera_frame=np.full(n, detections_frame),
        u=seen.u,
        v=seen.v,
        depth_m=np.full(n, np.nan) if spec.depth_images else recorded_depth,
        label=np.full(n, "cup"),
        score=np.full(n, 0.9),
        source=np.full(n, TOPICS.detections or ""),
    )
    cameras = CameraTable(
        frame=np.full(n, detections_frame),
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
    return observations, cameras, obs_stamp, log_delay


def _robot_points(spec: SceneSpec, robot: _ChainParams, motion: _Motion, seen: _Seen, body_from_footprint: FloatArray
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The robot's own computation, from the same pixels and measured depth, with its parameters:
    its camera, body and world points."""
    robot_cam = rigid.back_project(robot.K, seen.u, seen.v, seen.depth_m * robot.depth_factor)
    body_from_camera = _base_from_camera(spec, robot)
    if robot.invert_camera:
        body_from_camera = rigid.inverse(body_from_camera)
    robot_body = rigid.apply(body_from_camera, robot_cam @ robot.cam_permutation.T)
    pose_ns = seen.capture_ns + robot.pose_offset_ns
    if robot.hold_ns is not None:
        pose_ns = rigid.held(motion.odom_ns, seen.capture_ns - robot.hold_ns)
    world_from_body = motion.world_from_base(robot.world, pose_ns)
    if robot.body == FOOTPRINT_FRAME:
        world_from_body = world_from_body @ body_from_footprint
    if robot.invert_pose:
        world_from_body = rigid.inverse(world_from_body)
    return robot_cam, robot_body, rigid.apply(world_from_body, robot_body)


def _base_from_camera(spec: SceneSpec, params: _ChainParams) -> FloatArray:
    """``T_base_link_X`` with X the optical frame (or camera_link when the optical edge is skipped)."""
    mount = rigid.matrix(np.asarray(spec.mount_xyz, dtype=float) + params.mount_offset, params.mount_quat)
    if params.skip_optical_edge:
        return mount
    if params.sibling_optical:
        sibling: FloatArray = mount @ rigid.matrix([0.0, 0.0, 0.0], OPTICAL_FROM_LINK_QUAT_XYZW)
        return sibling
    out: FloatArray = mount @ rigid.matrix(spec.optical_xyz, params.optical_quat)
    return out


def _inject(params: _ChainParams, fault: InjectedFault, truth: _ChainParams) -> _ChainParams:
    p = fault.params
    kind = fault.kind
    if kind == Fault.LATENCY:
        if "hold_s" in p:
            return replace(params, hold_ns=round(float(p["hold_s"]) * 1e9))
        return replace(params, pose_offset_ns=round(float(p["offset_s"]) * 1e9))
    if kind == Fault.ROTATION_ERROR:
        error = Rotation.from_rotvec(np.deg2rad(float(p["angle_deg"])) * _unit(p.get("axis", (0, 0, 1))))
        return replace(params, mount_quat=(error * Rotation.from_quat(truth.mount_quat)).as_quat())
    if kind == Fault.MISSING_ROTATION:
        return replace(params, mount_quat=np.array([0.0, 0.0, 0.0, 1.0]))
    if kind == Fault.TRANSLATION_ERROR:
        return replace(params, mount_offset=np.asarray(p["offset_m"], dtype=float))
    if kind == Fault.AXIS_FLIP:
        if fault.used_frame is not None:
            if fault.used_frame != MOUNT_FRAME:
                raise SceneError(f"axis_flip used={fault.used_frame!r}: only {MOUNT_FRAME!r} can stand in for the "
                                 "optical frame")
            return replace(params, skip_optical_edge=True)
        return replace(params, cam_permutation=np.asarray(p["permutation"], dtype=float))
    if kind == Fault.DEPTH_SCALE:
        return replace(params, depth_factor=float(p["factor"]))
    if kind == Fault.INTRINSICS:
        k = truth.K.copy()
        if p.get("variant") == "focal":  # another lens: the focal length alone
            k[:2, :2] *= float(p["scale"])
        else:
            k[:2, :] *= float(p["scale"])  # the K of another resolution: focal and principal point scale
        return replace(params, K=k)
    if kind == Fault.WRONG_WORLD_FRAME:
        if fault.used_frame == FOOTPRINT_FRAME:
            return replace(params, body=FOOTPRINT_FRAME)
        if fault.used_frame != "odom":
            raise SceneError(f"wrong_world_frame used={fault.used_frame!r}: 'odom' or {FOOTPRINT_FRAME!r}")
        return replace(params, world="odom")
    if kind == Fault.WRONG_CAMERA_FRAME:
        if fault.used_frame != DEPTH_OPTICAL_FRAME:
            raise SceneError(f"wrong_camera_frame used={fault.used_frame!r}: only {DEPTH_OPTICAL_FRAME!r} is published")
        return replace(params, sibling_optical=True)
    if kind == Fault.INVERTED_TRANSFORM:
        if fault.hop == "body_to_world":
            return replace(params, invert_pose=True)
        return replace(params, invert_camera=True)
    raise SceneError(f"unknown fault {kind}")


def _inject_data(params: _ChainParams, fault: InjectedFault, truth: _ChainParams) -> _ChainParams:
    """A fault in the recorded data: what the log says differs from what the robot used."""
    robot_only = (
        fault.kind == Fault.WRONG_WORLD_FRAME
        or (fault.kind == Fault.INVERTED_TRANSFORM and fault.hop == "body_to_world")
        or (fault.used_frame is not None and fault.kind != Fault.AXIS_FLIP)
        or "hold_s" in fault.params
    )
    if robot_only:
        raise SceneError(f"{fault.kind.value} at {fault.hop} ({fault.params}) is a fault of the robot's computation "
                         "only; drop @data")
    if fault.kind == Fault.AXIS_FLIP and fault.used_frame is not None:
        # The detections (and their CameraInfo) name camera_link while their pixels are optical: the
        # recorded data skips the optical edge (a driver configured with the link as its frame_id).
        if fault.used_frame != MOUNT_FRAME:
            raise SceneError(f"axis_flip used={fault.used_frame!r}: only {MOUNT_FRAME!r} can stand in for the "
                             "optical frame")
        return replace(params, detections_frame=MOUNT_FRAME)
    if fault.kind == Fault.AXIS_FLIP:
        # A recorded rotation can only permute axes properly (det +1): the optical edge published wrong.
        perm = np.asarray(fault.params["permutation"], dtype=float)
        if not np.isclose(np.linalg.det(perm), 1.0):
            raise SceneError("a recorded axis flip must be a proper rotation (det +1)")
        wrong = Rotation.from_quat(truth.optical_quat) * Rotation.from_matrix(perm)
        return replace(params, optical_quat=wrong.as_quat())
    return _inject(params, fault, truth)


def ns(t_s: FloatArray) -> IntArray:
    """Seconds since the episode start to absolute nanoseconds."""
    out: IntArray = START_NS + np.round(t_s * 1e9).astype(np.int64)
    return out


def _unit(axis: Sequence[float]) -> FloatArray:
    a = np.asarray(axis, dtype=float)
    out: FloatArray = a / np.linalg.norm(a)
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
            table(spec.optical_frame, robot_cam, PointRole.HOP_CAMERA, HOP_TOPICS.camera or ""),
            table(BODY_FRAME, robot_body, PointRole.HOP_BODY, HOP_TOPICS.body or ""),
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
