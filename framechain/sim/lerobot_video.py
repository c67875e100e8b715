"""LeRobot episodes with wrist video, generated with known faults: the camera-motion evidence's truth.

One or two SO-101 arms, or ALOHA's ViperX 300 6DOF (``arm="aloha"``), (bimanual: link and joint names
prefixed ``left_``/``right_``) move along smooth joint trajectories; a wrist camera rides on a ``gripper_link``.
Each frame is rendered by :class:`framechain.sim.video_scene.TexturedScene` from the camera's pose at the
moment the frame was taken, computed with this package's own URDF maths (:mod:`framechain.sim.urdf_chain`; never
framechain's kinematics, replay or camera model), encoded with PyAV, and written as a LeRobot
v3.0 or v2.1 dataset with :func:`framechain.adapters.lerobot.writer.write_lerobot_dataset`.

Faults, all known to the returned :class:`VideoDatasetTruth`:

- ``video_delay_s``: frames late by this (frame k, stamped ``k / fps``, shows the scene at
  ``k / fps - delay``): the expected offset is ``-delay`` (framechain's latency sign);
- ``mount_error_deg`` about ``mount_error_axis`` (optical frame): the declared mount is
  ``R_declared = R_true exp(angle * axis)``;
- ``declared_arm``: the camera is declared on another arm than the one carrying it;
- ``focal_scale``: the declared intrinsics' focal length is this times the true one;
- ``repeat_share``: this share of frames repeat the previous frame exactly (a late camera), on the
  same rows in every camera (as a real recorder resends when its loop is late);
- ``camera_delays_s`` / ``episode_delays_s``: a delay of one camera, or of one episode, on top.

And the ways real recordings depart from LeRobot's own writer, each switched on its own:

- ``clock="realtime"``: the rows' ``timestamp`` are the real capture times, at a variable rate about
  ``realtime_hz`` (18.6 Hz in a real SO-101 recording), while each video holds exactly one frame per
  row encoded at the nominal ``fps`` (so ``timestamp`` departs from ``frame_index / fps``, by seconds
  at the end of a long episode); the default ``"presentation"`` writes ``timestamp = frame_index / fps``;
- ``camera_per_arm``: a wrist camera on each arm of a bimanual robot (``observation.images.left_wrist``
  and ``right_wrist``), and ``swap_cameras``: each declared on the other arm;
- ``black_first_episode``: that camera's first episode is all black (a camera that delivered nothing);
- ``table="cloth"``: a low-texture table (a cloth's faint weave) under the camera;
- ``codec="mpeg4"`` at 224x224 and a wide lens (``focal_px`` about 100 to 125) are spec values.

State is LeRobot's SO-101 convention: joints in degrees (``shoulder_pan.pos``, ...), the gripper
0-100; or ALOHA's: joints in radians (``left_waist``, ...), the gripper the fingers' opening 0..1. Actions are
the next frame's state.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset
from framechain.arrays import FloatArray
from framechain.config.mobile_base import DEFAULT_FRAME as BASE_FRAME
from framechain.robot.known_arms import BASE_VELOCITIES
from framechain.sim.lerobot_encoding import frames_feature, realtime_stamps, write_videos
from framechain.sim.mobile_base import (
    ARM_ON_BASE,
    FRONT_ON_BASE,
    BaseMotion,
    base_motion,
)
from framechain.sim.urdf_chain import UrdfChain, rpy_matrix
from framechain.sim.video_scene import PadRegion, TexturedScene, pixel_rays, png_bytes

__all__ = ["ARMS", "ARM_JOINTS", "ArmKind", "CameraTruth", "VideoDatasetSpec", "VideoDatasetTruth",
           "generate_video_dataset", "gripper_pads", "write_robot_yaml"]

ARM_JOINTS = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll")


@dataclass(frozen=True)
class ArmKind:
    """One arm model as the generator moves and records it."""

    #: The URDF joints that move, from the base out, and their state names (after the arm's prefix).
    joints: tuple[str, ...]
    #: A pose with the gripper reaching forward and down over the table (rad).
    home: FloatArray
    #: Amplitudes (rad) of each joint's motion; frequencies (rad/s) are drawn per episode.
    amplitude: FloatArray
    #: The camera's optical axes in the link it rides (columns).
    optical_in_link: FloatArray
    #: "deg" (LeRobot's SO-101: ``shoulder_pan.pos``, the gripper 0-100) or "rad" (ALOHA's: ``waist``, the gripper
    #: 0..1).
    unit: str
    #: What follows the joint in a state name: ".pos" (SO-101's ``shoulder_pan.pos``) or "" (ALOHA's ``waist``).
    suffix: str
    #: LeRobot's ``robot_type`` of one arm, of two.
    robot_types: tuple[str, str]
    camera_link: str = "gripper_link"


#: The arms the generator knows. SO-101: its camera looks along the jaws (gripper_link's -z), image up +x, tilted
#: down 25 deg. ALOHA's ViperX 300 6DOF: gripper_link's x runs along the jaws, z up; the camera on top of the gripper
#: looks along them, tilted down 20 deg.
ARMS = {
    "so101": ArmKind(ARM_JOINTS, np.array([0.0, -0.6, 0.5, 0.6, 0.0]), np.array([0.45, 0.2, 0.2, 0.3, 0.6]),
                     np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]) @ rpy_matrix((-0.436, 0, 0)),
                     "deg", ".pos", ("so101_follower", "bi_so101_follower")),
    "aloha": ArmKind(("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate"),
                     np.array([0.0, 0.3, 0.3, 0.0, 0.5, 0.0]), np.array([0.4, 0.1, 0.1, 0.3, 0.25, 0.5]),
                     np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]) @ rpy_matrix((-0.35, 0, 0)),
                     "rad", "", ("viperx", "aloha")),
}


@dataclass(frozen=True)
class VideoDatasetSpec:
    """What to generate: arms, cameras, episodes, format, the clock, and the faults to inject."""

    urdf: Path
    seed: int = 0
    #: The arm model (:data:`ARMS`): "so101" or "aloha" (``urdf`` its URDF).
    arm: str = "so101"
    episodes: int = 1
    duration_s: float = 6.0
    fps: int = 30
    version: str = "v3.0"
    codec: str = "libx264"
    bimanual: bool = False
    #: The arm carrying the camera and the arm it is declared on ("" single arm; "left_"/"right_").
    camera_arm: str = ""
    declared_arm: str | None = None
    #: A wrist camera on every arm (bimanual), each declared on the other arm when ``swap_cameras``.
    camera_per_arm: bool = False
    swap_cameras: bool = False
    width: int = 224
    height: int = 224
    focal_px: float = 180.0
    mount_xyz: tuple[float, float, float] = (0.05, 0.0, -0.03)
    video_delay_s: float = 0.0
    #: Per camera (in the order of ``VideoDatasetTruth.cameras``) and per episode: delays added to ``video_delay_s``.
    camera_delays_s: tuple[float, ...] = ()
    episode_delays_s: tuple[float, ...] = ()
    mount_error_deg: float = 0.0
    mount_error_axis: tuple[float, float, float] = (0.6, 0.8, 0.0)
    focal_scale: float = 1.0
    repeat_share: float = 0.0
    pads: bool = True
    #: The arms hold still (a camera that shows nothing of its motion).
    still: bool = False
    #: Only these of the arm's joints move (an arm that only pans: ``("shoulder_pan",)``); None: all of them.
    moving_joints: tuple[str, ...] | None = None
    #: "presentation": ``timestamp = frame_index / fps``; "realtime": real capture times at about ``realtime_hz``.
    clock: str = "presentation"
    realtime_hz: float = 18.6
    #: The camera (its name: "wrist", "left_wrist", ...) whose first episode is all black ("": none).
    black_first_episode: str = ""
    #: "rich": a textured table; "cloth": a low-texture one.
    table: str = "rich"
    #: A marker lying on the table under the camera's mean view (0: none): its side (m), id, dictionary.
    marker_size_m: float = 0.0
    marker_id: int = 7
    marker_dictionary: str = "DICT_4X4_50"
    #: Frames as an mp4 per key ("video"), or PNG bytes in the Parquet ("image", an HF Image feature).
    storage: str = "video"
    #: Encoder options beside the fast preset, e.g. (("bf", "0"), ("g", "2")): no B-frames, key frames every 2.
    codec_options: tuple[tuple[str, str], ...] = ()
    #: A mobile base turning up to this many degrees either way (LeKiwi: ``arm_`` names, ``x.vel``, ``y.vel``,
    #: ``theta.vel`` recorded too); 0: the arm stands in the world.
    base_turn_deg: float = 0.0
    #: LeKiwi's front camera on the mobile base too (after the wrist camera; needs ``base_turn_deg``).
    front_camera: bool = False

    def __post_init__(self) -> None:
        if self.base_turn_deg and self.bimanual:
            raise ValueError("base_turn_deg: the generated mobile base (LeKiwi's) carries one arm")
        if self.front_camera and not self.base_turn_deg:
            raise ValueError("front_camera rides the mobile base: give base_turn_deg")

    @property
    def prefix(self) -> str:
        """What comes before a joint in a one-arm state name (LeKiwi's ``arm_``)."""
        return "arm_" if self.base_turn_deg else ""

    def delay_s(self, camera: int, episode: int) -> float:
        """How late camera ``camera``'s frames of episode ``episode`` are (s)."""
        extra = self.camera_delays_s[camera] if camera < len(self.camera_delays_s) else 0.0
        shift = self.episode_delays_s[episode] if episode < len(self.episode_delays_s) else 0.0
        return self.video_delay_s + extra + shift


@dataclass(frozen=True)
class CameraTruth:
    """One wrist camera: where it truly is, where robot.yaml declares it, what its frames hold."""

    name: str
    video_key: str
    arm: str  # the arm carrying it ("", "left_", "right_")
    declared_arm: str
    camera_link: str
    declared_link: str
    q_link_cam: FloatArray  # true R_link_cam (xyzw)
    declared_q_link_cam: FloatArray
    #: Per episode: how late its frames are (s); framechain's offset is minus this.
    delays_s: tuple[float, ...]
    black_episodes: tuple[int, ...] = ()
    #: Where it is on its link (None: the wrist camera's ``spec.mount_xyz``).
    xyz_link_cam: FloatArray | None = None


@dataclass(frozen=True)
class VideoDatasetTruth:
    """The dataset written and everything true about it (frames in the camera's optical frame).

    The single-camera fields describe the first camera; ``cameras`` holds every one.
    """

    root: Path
    spec: VideoDatasetSpec
    video_key: str
    arms: tuple[str, ...]
    state_names: tuple[str, ...]
    camera_link: str
    declared_link: str
    q_link_cam: FloatArray  # true R_link_cam (xyzw)
    declared_q_link_cam: FloatArray
    xyz_link_cam: FloatArray
    #: True fx, fy, cx, cy and the declared focal length.
    intrinsics: tuple[float, float, float, float]
    declared_focal_px: float
    #: Per episode: the frames (in order) that repeat the previous one (the same rows in every camera).
    repeated: tuple[tuple[int, ...], ...] = field(default_factory=tuple)
    #: The marker's centre in the world (NaN: none).
    marker_xyz: tuple[float, float, float] = (float("nan"), float("nan"), float("nan"))
    cameras: tuple[CameraTruth, ...] = ()
    #: Per episode: the rows' timestamps as written (s from the episode's start).
    timestamps_s: tuple[FloatArray, ...] = ()
    #: Per episode: the mobile base's motion (none without one).
    base_motions: tuple[BaseMotion, ...] = ()

    @property
    def expected_offset_s(self) -> float:
        """framechain's latency offset for the injected delay: frames late by d give ``-d``."""
        return -self.spec.video_delay_s

    def camera(self, name: str) -> CameraTruth:
        return next(c for c in self.cameras if c.name == name)


def _trajectory(rng: np.random.Generator, kind: ArmKind, *, still: bool = False,
                moving: tuple[str, ...] | None = None) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per joint: amplitude (rad), frequency (rad/s) and phase of two summed sines (a varying speed); the joints not
    ``moving`` (None: all move) hold their home angle."""
    if moving is not None and not set(moving) <= set(kind.joints):
        raise ValueError(f"moving_joints {sorted(set(moving) - set(kind.joints))} are not among {kind.joints}")
    n = len(kind.joints)
    moves = np.array([moving is None or name in moving for name in kind.joints], dtype=float)
    amplitude = kind.amplitude[:, None] * rng.uniform(0.5, 0.8, (n, 2)) * (0.0 if still else 1.0) * moves[:, None]
    omega = rng.uniform(0.8, 2.2, (n, 2))
    phase = rng.uniform(0.0, 2 * np.pi, (n, 2))
    return amplitude, omega, phase


def _joints(kind: ArmKind, motion: tuple[FloatArray, FloatArray, FloatArray], t_s: FloatArray) -> FloatArray:
    """(T, joints) arm joint angles (rad) at times ``t_s``."""
    amplitude, omega, phase = motion
    waves = amplitude[None] * np.sin(omega[None] * t_s[:, None, None] + phase[None])
    out: FloatArray = kind.home + waves.sum(axis=2)
    return out


def _base_poses(arms: Sequence[str]) -> dict[str, FloatArray]:
    """``T_world_base`` per arm: side by side 0.4 m apart, both facing +x."""
    out = {}
    for arm in arms:
        pose = np.eye(4)
        pose[1, 3] = {"left_": 0.2, "right_": -0.2}.get(arm, 0.0)
        out[arm] = pose
    return out


def _mounts(spec: VideoDatasetSpec) -> tuple[FloatArray, FloatArray]:
    """True and declared ``T_link_cam`` (4x4, optical frame)."""
    true = np.eye(4)
    true[:3, :3] = ARMS[spec.arm].optical_in_link
    true[:3, 3] = spec.mount_xyz
    axis = np.asarray(spec.mount_error_axis, dtype=float)
    error = Rotation.from_rotvec(np.deg2rad(spec.mount_error_deg) * axis / np.linalg.norm(axis)).as_matrix()
    declared = true.copy()
    declared[:3, :3] = true[:3, :3] @ error
    return true, declared


def gripper_pads(width: int, height: int) -> tuple[PadRegion, ...]:
    """The gripper's jaws in the lower corners of the image."""
    w, h = width, height
    left = ((0, h), (0, int(0.83 * h)), (int(0.22 * w), int(0.76 * h)), (int(0.36 * w), h))
    right = ((w, h), (w, int(0.83 * h)), (int(0.78 * w), int(0.76 * h)), (int(0.64 * w), h))
    return PadRegion(left, 1), PadRegion(right, 2)


def _camera_layout(spec: VideoDatasetSpec, arms: tuple[str, ...]) -> list[tuple[str, str, str]]:
    """(name, carrying arm, declared arm) of each camera."""
    if spec.camera_per_arm:
        if len(arms) != 2:
            raise ValueError("camera_per_arm needs a bimanual robot")
        other = {arms[0]: arms[1], arms[1]: arms[0]}
        return [(f"{arm}wrist", arm, other[arm] if spec.swap_cameras else arm) for arm in arms]
    declared = spec.camera_arm if spec.declared_arm is None else spec.declared_arm
    return [("wrist", spec.camera_arm, declared), *([("front", BASE_FRAME, BASE_FRAME)] if spec.front_camera else [])]


def _episode_stamps(rng: np.random.Generator, spec: VideoDatasetSpec) -> FloatArray:
    if spec.clock == "realtime":
        return realtime_stamps(rng, spec.duration_s, spec.realtime_hz)
    if spec.clock != "presentation":
        raise ValueError(f"clock {spec.clock!r}: presentation or realtime")
    out: FloatArray = np.arange(round(spec.duration_s * spec.fps)) / spec.fps
    return out


@dataclass(frozen=True)
class _Rig:
    """What places a camera in the world: the arms' chains and bases, and the wrist camera's true mount."""

    kind: ArmKind
    chains: dict[str, UrdfChain]
    bases: dict[str, FloatArray]
    mount: FloatArray

    def world_from_cam(self, arm: str, motions: dict[str, tuple[FloatArray, FloatArray, FloatArray]],
                       base: BaseMotion | None, seen: FloatArray) -> FloatArray:
        """``T_world_cam`` (T, 4, 4) at the moments ``seen`` of the wrist camera ``arm`` carries, or of the front
        camera on the mobile base (``arm`` the base's frame)."""
        if arm == BASE_FRAME and base is not None:
            out: FloatArray = base.world_from_base(seen) @ FRONT_ON_BASE
        else:
            joints = dict(zip(self.kind.joints, _joints(self.kind, motions[arm], seen).T, strict=True))
            stands = self.bases[arm] if base is None else base.world_from_base(seen) @ ARM_ON_BASE
            out = stands @ self.chains[arm].root_from_link(joints, f"{arm}{self.kind.camera_link}") @ self.mount
        return out


def generate_video_dataset(root: str | Path, spec: VideoDatasetSpec) -> VideoDatasetTruth:
    """Render, encode and write the dataset under ``root`` (created); return its truth."""
    rng = np.random.default_rng(spec.seed)
    kind = ARMS[spec.arm]
    arms = ("left_", "right_") if spec.bimanual else ("",)
    if not spec.camera_per_arm and (spec.camera_arm not in arms or spec.declared_arm not in (None, *arms)):
        raise ValueError(f"camera arm {spec.camera_arm!r} / declared {spec.declared_arm!r}: arms are {arms}")
    layout = _camera_layout(spec, arms)
    scene = TexturedScene(rng, table_style=spec.table)
    cx, cy = (spec.width - 1) / 2.0, (spec.height - 1) / 2.0
    rays = pixel_rays(spec.focal_px, spec.focal_px, cx, cy, spec.width, spec.height)
    mount, declared_mount = _mounts(spec)
    rig = _Rig(kind, {arm: UrdfChain(spec.urdf, prefix=arm) for arm in {a for _n, a, _d in layout} - {BASE_FRAME}},
               _base_poses(arms), mount)
    pads = gripper_pads(spec.width, spec.height) if spec.pads else ()
    names = tuple(f"{arm or spec.prefix}{joint}{kind.suffix}" for arm in arms for joint in (*kind.joints, "gripper"))
    names += tuple(BASE_VELOCITIES.values()) if spec.base_turn_deg else ()
    keys = [f"observation.images.{name}" for name, _a, _d in layout]
    episodes, repeated, stamps, base_motions = [], [], [], []
    videos: dict[str, list[np.ndarray]] = {key: [] for key in keys}
    marker = (float("nan"), float("nan"), float("nan"))
    for e in range(spec.episodes):
        t = _episode_stamps(rng, spec)
        n = t.size
        motions = {arm: _trajectory(rng, kind, still=spec.still, moving=spec.moving_joints) for arm in arms}
        base = base_motion(rng, spec.base_turn_deg) if spec.base_turn_deg else None
        base_motions += [] if base is None else [base]
        state = np.concatenate([_state(kind, motions[arm], t) for arm in arms]
                               + ([] if base is None else [base.recorded(t)]), axis=1)
        repeats = np.flatnonzero(rng.random(n) < spec.repeat_share)
        repeats = repeats[repeats > 0]
        repeated.append(tuple(int(k) for k in repeats))
        columns: dict[str, np.ndarray] = {"observation.state": state, "action": np.concatenate([state[1:], state[-1:]])}
        for c, ((name, arm, _declared), key) in enumerate(zip(layout, keys, strict=True)):
            world_from_cam = rig.world_from_cam(arm, motions, base, t - spec.delay_s(c, e))
            if e == 0 and c == 0 and spec.marker_size_m > 0:
                marker = scene.place_marker(world_from_cam, spec.marker_dictionary, spec.marker_id,
                                            spec.marker_size_m)
            shown = pads if arm != BASE_FRAME else ()
            frames = np.stack([scene.render(pose, rays, shown) for pose in world_from_cam])
            for k in repeats:  # in order, so runs of repeats all show the frame before the run
                frames[k] = frames[k - 1]
            if e == 0 and name == spec.black_first_episode:
                frames = _black_frames(rng, frames.shape)
            videos[key].append(frames)
            if spec.storage == "image":
                columns[key] = np.array([png_bytes(f) for f in frames], dtype=object)
        episodes.append(EpisodeData(frames=columns, timestamp_s=None if spec.clock == "presentation" else t))
        stamps.append(t)
    out = Path(root)
    write_lerobot_dataset(out, episodes, features=_features(spec, names, keys), fps=spec.fps, version=spec.version,
                          robot_type="lekiwi" if spec.base_turn_deg else kind.robot_types[1 if spec.bimanual else 0])
    if spec.storage == "video":
        for key in keys:
            write_videos(out, key, videos[key], fps=spec.fps, codec=spec.codec, version=spec.version,
                         options=spec.codec_options)
    return _truth(out, spec, layout, keys, arms=arms, names=names, mounts=(mount, declared_mount),
                  repeated=tuple(repeated), marker=marker, stamps=tuple(stamps), base_motions=tuple(base_motions))


def _truth(
    out: Path, spec: VideoDatasetSpec, layout: Sequence[tuple[str, str, str]], keys: Sequence[str], *,
    arms: tuple[str, ...], names: tuple[str, ...], mounts: tuple[FloatArray, FloatArray],
    repeated: tuple[tuple[int, ...], ...], marker: tuple[float, float, float], stamps: tuple[FloatArray, ...],
    base_motions: tuple[BaseMotion, ...] = (),
) -> VideoDatasetTruth:
    """What the dataset written under ``out`` truly is: each camera's link, mount and delays, as declared and as
    rendered (``mounts``: the true and the declared link-from-camera transforms)."""
    mount, declared_mount = mounts
    q_true = Rotation.from_matrix(mount[:3, :3]).as_quat()
    q_declared = Rotation.from_matrix(declared_mount[:3, :3]).as_quat()
    cameras = tuple(CameraTruth(
        name=name, video_key=key, arm=arm, declared_arm=declared, camera_link=f"{arm}{ARMS[spec.arm].camera_link}",
        declared_link=f"{declared}{ARMS[spec.arm].camera_link}", q_link_cam=q_true, declared_q_link_cam=q_declared,
        delays_s=tuple(spec.delay_s(c, e) for e in range(spec.episodes)),
        black_episodes=(0,) if name == spec.black_first_episode else ())
        if arm != BASE_FRAME else _front_truth(spec, name, key, c)
        for c, ((name, arm, declared), key) in enumerate(zip(layout, keys, strict=True)))
    first = cameras[0]
    cx, cy = (spec.width - 1) / 2.0, (spec.height - 1) / 2.0
    return VideoDatasetTruth(
        root=out, spec=spec, video_key=first.video_key, arms=arms, state_names=names,
        camera_link=first.camera_link, declared_link=first.declared_link, q_link_cam=q_true,
        declared_q_link_cam=q_declared, xyz_link_cam=np.asarray(spec.mount_xyz, dtype=float),
        intrinsics=(spec.focal_px, spec.focal_px, cx, cy), declared_focal_px=spec.focal_px * spec.focal_scale,
        repeated=repeated, marker_xyz=marker, cameras=cameras, timestamps_s=stamps, base_motions=base_motions,
    )


def _front_truth(spec: VideoDatasetSpec, name: str, key: str, c: int) -> CameraTruth:
    """LeKiwi's front camera: on the mobile base, declared where it is."""
    q, on = Rotation.from_matrix(FRONT_ON_BASE[:3, :3]).as_quat(), BASE_FRAME
    return CameraTruth(name, key, on, on, on, on, q, q, xyz_link_cam=FRONT_ON_BASE[:3, 3],
                       delays_s=tuple(spec.delay_s(c, e) for e in range(spec.episodes)))


def _features(spec: VideoDatasetSpec, names: tuple[str, ...], keys: Sequence[str]) -> dict[str, FeatureSpec]:
    out = {
        "observation.state": FeatureSpec("float32", (len(names),), list(names)),
        "action": FeatureSpec("float32", (len(names),), list(names)),
    }
    for key in keys:
        out[key] = frames_feature(spec.width, spec.height, fps=spec.fps, codec=spec.codec, storage=spec.storage)
    return out


def _black_frames(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """A camera that delivered nothing: sensor noise a few grey levels above black."""
    out: np.ndarray = rng.integers(0, 6, size=shape, dtype=np.uint8)
    return out


def _state(kind: ArmKind, motion: tuple[FloatArray, FloatArray, FloatArray], t_s: FloatArray) -> FloatArray:
    """(T, joints + 1) state: SO-101's joints in degrees and the gripper 0-100, or ALOHA's in radians and 0..1."""
    joints = _joints(kind, motion, t_s)
    if kind.unit == "deg":
        joints, gripper = np.rad2deg(joints), 50.0 + 20.0 * np.sin(0.7 * t_s)
    else:
        gripper = 0.5 + 0.3 * np.sin(0.7 * t_s)
    out: FloatArray = np.concatenate([joints, gripper[:, None]], axis=1)
    return out


def write_robot_yaml(truth: VideoDatasetTruth, path: str | Path, *, extra: dict[str, object] | None = None) -> Path:
    """robot.yaml as a user would write it for the dataset: the URDF, the joints (SO-101: degrees, the gripper
    0-100; ALOHA: radians, its gripper's 0..1 driving nothing), each arm's base, and the wrist camera with its
    *declared* intrinsics, mount and arm."""
    import yaml

    spec = truth.spec
    kind = ARMS[spec.arm]
    _fx, _fy, cx, cy = truth.intrinsics

    def joints(arm: str) -> dict[str, object]:
        named = arm or spec.prefix
        out: dict[str, object] = {f"{named}{j}{kind.suffix}": j for j in kind.joints}
        if kind.unit == "deg":
            out[f"{named}gripper.pos"] = {"joint": "gripper", "unit": "range_0_100"}
        return out

    def camera(cam: CameraTruth) -> dict[str, object]:
        return {
            "intrinsics": {"fx": truth.declared_focal_px, "fy": truth.declared_focal_px, "cx": cx, "cy": cy,
                           "width": spec.width, "height": spec.height},
            "mount": {"parent": cam.declared_link,
                      "xyz": [float(v) for v in (truth.xyz_link_cam if cam.xyz_link_cam is None else cam.xyz_link_cam)],
                      "quat_xyzw": [float(v) for v in cam.declared_q_link_cam], "optical": True},
            "video_key": cam.video_key,
        }

    config: dict[str, object] = {"state_feature": "observation.state"}
    if truth.arms == ("",):
        config.update(urdf=str(spec.urdf), default_unit=kind.unit, joints=joints(""))
        if spec.base_turn_deg:
            config["world_from_base"] = {"xyz": [float(v) for v in ARM_ON_BASE[:3, 3]], "rpy": [0.0, 0.0, 0.0]}
            config["mobile_base"] = dict(BASE_VELOCITIES)
    else:
        bases = _base_poses(truth.arms)
        config["arms"] = {arm.rstrip("_"): {"urdf": str(spec.urdf), "prefix": arm, "default_unit": kind.unit,
                                            "world_from_base": {"xyz": [float(v) for v in bases[arm][:3, 3]],
                                                                "rpy": [0.0, 0.0, 0.0]},
                                            "joints": joints(arm)}
                          for arm in truth.arms}
    config["cameras"] = {cam.name: camera(cam) for cam in truth.cameras}
    config.update(extra or {})
    out = Path(path)
    out.write_text(yaml.safe_dump(config, sort_keys=False))
    return out
