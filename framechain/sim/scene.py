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

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from framechain.arrays import FloatArray, IntArray
from framechain.catalogue import Fault
from framechain.config.chain import ChainConfig, ChainEvidence, ChainFrames
from framechain.geometry.conventions import OPTICAL_FROM_LINK_QUAT_XYZW
from framechain.sim import rigid
from framechain.sim.faults import ChainParams, faulty_params
from framechain.sim.render import render_color, render_depth
from framechain.sim.spec import (
    BODY_FRAME,
    COLOR_TOPIC,
    DEPTH_OPTICAL_FRAME,
    FOOTPRINT_FRAME,
    HOP_TOPICS,
    MOUNT_FRAME,
    REALSENSE_OPTICAL_FRAME,
    REALSENSE_OPTICAL_XYZ,
    REFERENCE_TOPIC,
    START_NS,
    TARGET_TOPIC,
    TOPICS,
    ExpectedFinding,
    InjectedFault,
    SceneError,
    SceneSpec,
    expected_finding,
)
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

#: The scene's face: what it is asked to be (:mod:`framechain.sim.spec`) and the episode generated.
__all__ = [
    "REALSENSE_OPTICAL_FRAME",
    "REALSENSE_OPTICAL_XYZ",
    "START_NS",
    "TOPICS",
    "ExpectedFinding",
    "Fault",
    "InjectedFault",
    "Scene",
    "SceneError",
    "SceneSpec",
    "generate",
    "ns",
]


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
        return [expected_finding(self.spec, f) for f in self.spec.faults]


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
    truth = ChainParams(K=K_true, mount_quat=true_mount_q)
    recorded, robot = faulty_params(spec, truth)
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


def _static_tf(spec: SceneSpec, params: ChainParams, body_from_footprint: FloatArray | None) -> TransformTable:
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


def _capture(spec: SceneSpec, rng: np.random.Generator, motion: _Motion, truth: ChainParams, obj: FloatArray
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


def _recorded_detections(spec: SceneSpec, rng: np.random.Generator, recorded: ChainParams, seen: _Seen
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


def _robot_points(spec: SceneSpec, robot: ChainParams, motion: _Motion, seen: _Seen, body_from_footprint: FloatArray
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


def _base_from_camera(spec: SceneSpec, params: ChainParams) -> FloatArray:
    """``T_base_link_X`` with X the optical frame (or camera_link when the optical edge is skipped)."""
    mount = rigid.matrix(np.asarray(spec.mount_xyz, dtype=float) + params.mount_offset, params.mount_quat)
    if params.skip_optical_edge:
        return mount
    if params.sibling_optical:
        sibling: FloatArray = mount @ rigid.matrix([0.0, 0.0, 0.0], OPTICAL_FROM_LINK_QUAT_XYZW)
        return sibling
    out: FloatArray = mount @ rigid.matrix(spec.optical_xyz, params.optical_quat)
    return out


def ns(t_s: FloatArray) -> IntArray:
    """Seconds since the episode start to absolute nanoseconds."""
    out: IntArray = START_NS + np.round(t_s * 1e9).astype(np.int64)
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
