"""One LeRobot episode as a framechain Timeline: joint states, FK transforms, cameras, detections.

LeRobot datasets store joint states, actions and camera videos, but no transforms, no intrinsics
and no hardware timestamps. :func:`open_dataset` brings them in from the robot configuration
(robot.yaml, :mod:`framechain.adapters.robot.config`): the URDF and the mapping of state names to
joints give the transforms by batched forward kinematics, the calibration files give intrinsics
and camera mounts, and detections come from a side table or a dataset feature.

The Timeline holds:

- transforms: a static ``world -> <URDF root>`` edge (``world_from_base`` in robot.yaml); one
  edge per URDF joint ``parent_link -> child_link``, dynamic (one sample per frame, stamped with
  the frame's timestamp) for joints the dataset drives and their mimics, static for fixed and
  held joints; static camera mounts ``link -> <camera>_optical_frame`` (through
  ``<camera>_link`` when the mount is not optical). A wrist camera's extrinsic thus follows the
  live joint state.
- cameras: one row per calibrated camera (stamp 0: valid throughout).
- observations: detections, stamped with the **camera's** time of their frame (the frame's
  timestamp, plus the camera's ``timing.offset_s``, or its ``timing.timestamp_column``); their
  ``log_time_ns`` is the frame's dataset timestamp, the time the state was recorded. So
  ``stamp_ns - log_time_ns`` is each observation's camera-vs-state gap, and the replay's
  per-hop gaps and stale accounting see the same offsets as for bags.
- joint_states: the mapped joints in SI units (long form, one row per joint per frame).
- depth_frames: per-frame depth features of the cameras that have one.

Times are nanoseconds from the episode start (LeRobot timestamps restart at 0 per episode).
``metadata["episode_start_ns"]`` is the first row's stamp, and ``metadata["wall_clock_start_ns"]`` that
row's wall-clock time where the dataset stores one (:mod:`framechain.adapters.lerobot.wall_clock`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from framechain.adapters.errors import AdapterError
from framechain.adapters.lerobot.camera_frames import camera_frames, depth_frames, episode_clock
from framechain.adapters.lerobot.clock import VideoClock
from framechain.adapters.lerobot.detections import episode_observations, with_markers
from framechain.adapters.lerobot.odometry import mobile_base_edge
from framechain.adapters.lerobot.reader import (
    DatasetError,
    DatasetReader,
    EpisodeFrames,
    FeatureInfo,
    Layout,
    is_lerobot_dataset,
)
from framechain.adapters.lerobot.wall_clock import wall_clock_features, wall_clock_start_ns
from framechain.adapters.model import LoadedLog
from framechain.arrays import FloatArray, IntArray
from framechain.config.calibration import CameraCalibration
from framechain.config.chain import ChainConfig
from framechain.config.chain_cameras import MarkerSpec
from framechain.config.robot import DetectionSource, RobotConfig, RobotConfigError
from framechain.robot.binding import arm_root, joint_positions, out_of_limits, robot_model, unit_mismatches
from framechain.robot.kinematics import RobotModel
from framechain.timeline import (
    CameraTable,
    DepthFrameTable,
    JointStateTable,
    LogInfo,
    Timeline,
    TopicInfo,
    TransformTable,
)

#: ``Timeline.metadata["format"]`` of a LeRobot episode.
FORMAT = "lerobot"

__all__ = ["FORMAT", "LeRobotAdapter", "camera_stamps_ns", "is_lerobot_dataset", "open_dataset", "scan_dataset"]


def open_dataset(
    path: str | Path,
    *,
    episode: int,
    robot: RobotConfig | str | Path,
    detections: str | Path | None = None,
    strict: bool = False,
    markers: MarkerSpec | None = None,
) -> Timeline:
    """Read episode ``episode`` of the LeRobot dataset at ``path`` into a Timeline.

    ``robot`` is a :class:`RobotConfig` or the path of robot.yaml; ``detections`` adds a side
    table (Parquet or CSV) to those robot.yaml names. ``strict`` turns metadata notes (harmless
    inconsistencies, listed in ``metadata["notes"]``) into :class:`DatasetError`. ``markers`` (else
    robot.yaml's ``chain.evidence.markers``) are searched in the chain camera's frames
    (:mod:`framechain.adapters.lerobot.markers`) and become observations too.
    """
    cfg = robot if isinstance(robot, RobotConfig) else RobotConfig.load(robot)
    reader = DatasetReader(path, strict=strict)
    model = robot_model(cfg)
    sources = list(cfg.detections)
    if detections is not None:
        sources.append(DetectionSource(table=Path(detections)))
    names = reader.names(cfg.state_feature)
    cfg.check_names(names)
    wall_features = wall_clock_features(reader)
    frames = reader.read(episode, list(dict.fromkeys([*_columns(cfg, reader, sources), *wall_features])))
    recorded = _finite_state(cfg, frames, names)
    q = joint_positions(cfg, model, recorded, names)
    state_ns = frames.stamp_ns
    source_name = f"{Path(path).name}:{cfg.state_feature}"

    transforms = TransformTable.concat([
        *_world_edges(cfg, model, recorded, names, state_ns, source_name),
        *_joint_edges(model, cfg, q, state_ns, source_name),
        *_mount_edges(cfg),
    ])
    cameras = CameraTable.concat([c.camera_table() for c in cfg.cameras.values()])
    cam_ns = {name: camera_stamps_ns(frames, cam) for name, cam in cfg.cameras.items()}
    observations = episode_observations(sources, cfg, frames, cam_ns, state_ns, episode, Path(path))
    depth = DepthFrameTable.concat([
        depth_frames(cam, frames, cam_ns[cam.name], state_ns) for cam in cfg.cameras.values() if cam.depth
    ])
    joint_states = _joint_states(cfg, q, state_ns, source_name)
    videos, clocks = camera_frames(cfg, frames, cam_ns, state_ns, reader.fps, Path(path))
    metadata = _metadata(Path(path), episode, cfg, model, reader, frames, clocks)
    metadata["notes"].extend([*unit_mismatches(cfg, recorded, names), *out_of_limits(cfg, model, q)])
    lost = frames.episode.missing_videos
    metadata["notes"].extend(missing_video_note(reader, lost[cam.video_key], cam.video_key, episode, cam.name)
                             for cam in cfg.cameras.values() if cam.video_key is not None and cam.video_key in lost)
    wall = wall_clock_start_ns(frames, wall_features)
    if wall is not None:
        metadata["wall_clock_feature"], metadata["wall_clock_start_ns"] = wall
    spec = markers or (cfg.evidence.markers if cfg.evidence is not None else None)
    if spec is not None:
        observations = with_markers(observations, videos, cameras, cfg, spec, metadata)
    return Timeline(transforms=transforms, cameras=cameras, observations=observations,
                    joint_states=joint_states, depth_frames=depth, image_frames=videos, metadata=metadata)


def _finite_state(cfg: RobotConfig, frames: EpisodeFrames, names: Sequence[str]) -> FloatArray:
    """The state feature's rows (frames, values); a mapped joint's value that is not finite is an error."""
    state = np.asarray(frames.columns[cfg.state_feature], dtype=float).reshape(len(frames), -1)
    base = cfg.mobile_base.states if cfg.mobile_base is not None else ()
    read = [names.index(s) for s in (*(m.state for m in cfg.joints), *base) if s in names]
    bad = ~np.isfinite(state[:, read])
    if bad.any():
        k = int(np.flatnonzero(bad.any(axis=1))[0])
        raise DatasetError(frames.episode.data_file, f"{cfg.state_feature} is not finite at frame {k}")
    return state


def _columns(cfg: RobotConfig, reader: DatasetReader, sources: Sequence[DetectionSource]) -> list[str]:
    """The per-frame columns an episode is read with; camera features of the wrong kind fail here."""
    for cam in cfg.cameras.values():
        if cam.video_key is not None:
            feat = reader.feature(cam.video_key)
            if not feat.is_video and feat.dtype != "image":
                raise RobotConfigError(cfg.source, f"camera {cam.name!r}: video_key {cam.video_key!r} is a "
                                       f"{feat.dtype} feature, not video or image")
            _check_image_size(cfg, cam, feat)
    columns = [cfg.state_feature]
    columns += [c.timing.timestamp_column for c in cfg.cameras.values() if c.timing.timestamp_column]
    # Frames stored in the Parquet (image features: PNG/JPEG bytes) rather than in an mp4.
    columns += [c.video_key for c in cfg.cameras.values()
                if c.video_key is not None and reader.feature(c.video_key).dtype == "image"]
    columns += [s.feature for s in sources if s.feature is not None]
    for cam in cfg.cameras.values():
        if cam.depth is not None:
            feat = reader.feature(cam.depth.feature)
            if feat.is_video or feat.dtype == "image":
                raise DatasetError(reader.root, f"depth feature {feat.key!r} of camera {cam.name!r} is "
                                   f"{'a video' if feat.is_video else 'an encoded image'}: framechain does not "
                                   "decode images; store depth as an array feature (height, width)")
            columns.append(cam.depth.feature)
    return list(dict.fromkeys(columns))


def _check_image_size(cfg: RobotConfig, cam: CameraCalibration, feature: FeatureInfo) -> None:
    """The camera's intrinsics are for the size of its images (info.json's feature): intrinsics calibrated at
    another size put every ray elsewhere, and the cameras' motion reads that as other faults."""
    size = feature.image_size
    i = cam.intrinsics
    if size is None or (i.width, i.height) == size:
        return
    width, height = size
    inline = cam.source == cfg.source  # declared under robot.yaml's cameras (else in its own calibration file)
    leaf = "intrinsics" if not i.source or i.source == cam.source else f"intrinsics_file ({i.source})"
    key = f"cameras.{cam.name}.{leaf}" if inline else leaf
    if i.width * height == i.height * width:  # the same aspect: the image was scaled
        scale = width / i.width
        fix = (f"the same aspect, scaled by {scale:.4g}: multiply fx, fy, cx, cy by {scale:.4g} "
               f"({width}/{i.width}) for this video")
    else:
        fix = f"give the intrinsics of the {width}x{height} images (calibrated at that size)"
    raise RobotConfigError(cam.source, f"{key} are for a {i.width}x{i.height} image, but {feature.key} is "
                           f"{width}x{height} (info.json features): {fix}")


def _metadata(path: Path, episode: int, cfg: RobotConfig, model: RobotModel, reader: DatasetReader,
              frames: EpisodeFrames, clocks: Mapping[str, VideoClock]) -> dict[str, Any]:
    """What the episode came from: dataset, robot configuration, joints held or at zero, cameras, chain."""
    held = {name: float(v) for name, v in cfg.hold.items()}
    driven = {m.joint for m in cfg.joints}
    zeroed = [j for j in model.actuated if j not in driven and j not in held]
    camera = cfg.cameras.get(cfg.chain_camera or next(iter(cfg.cameras), ""))
    chain = cfg.chain_config(root=arm_root(cfg, model, camera.mount.parent if camera else None)) \
        if cfg.cameras else None
    state_ns = frames.stamp_ns
    return {
        "format": FORMAT,
        "source": {"path": str(path.resolve()), "format": FORMAT, "episode": episode},
        "source_path": str(path.resolve()),
        "codebase_version": reader.version,
        "robot_type": reader.robot_type,
        "episode": episode,
        "fps": reader.fps,
        "length": len(frames),
        "tasks": list(frames.episode.tasks),
        "time_span_ns": [int(state_ns[0]), int(state_ns[-1])],
        # its first row: where the episode's own time starts (a viewer shows durations from it)
        "episode_start_ns": int(state_ns[0]),
        "state_feature": cfg.state_feature,
        "urdf": str(cfg.urdf),
        "robot_config": cfg.source,
        "joint_map": {m.state: {"joint": m.joint, "unit": m.unit.value, "sign": m.sign, "offset": m.offset}
                      for m in cfg.joints},
        "held_joints": held,
        "joints_at_zero": zeroed,
        "cameras": {
            name: {
                "frame": cam.optical_frame, "parent": cam.mount.parent, "optical_mount": cam.mount.optical,
                "xyz": list(cam.mount.xyz), "source": cam.source,
                "focal_px": [cam.intrinsics.fx, cam.intrinsics.fy],
                "video_key": cam.video_key, "timing": {"offset_s": cam.timing.offset_s,
                                                       "timestamp_column": cam.timing.timestamp_column},
                "video_file": _video_file(frames, cam.video_key),
                # the file info.json's video_path points to for the camera's video_key, when it is not on disk
                "video_missing": _missing_video(frames, cam.video_key),
                "video_from_s": frames.episode.video_from_s.get(cam.video_key or "", 0.0),
                "clock": clocks[name].to_json() if name in clocks else None,
            }
            for name, cam in cfg.cameras.items()
        },
        "chain_frames": None if chain is None else {"camera": chain.frames.camera, "body": chain.frames.body,
                                                    "world": chain.frames.world},
        "chain": None if chain is None else chain.to_dict(),
        "notes": [*reader.notes, *cfg.notes, *(c.summary() for c in clocks.values())],
    }


def camera_stamps_ns(frames: EpisodeFrames, camera: CameraCalibration) -> IntArray:
    """Per-frame capture time of ``camera``: its timestamp column (or the frame's), plus its offset."""
    timing = camera.timing
    if timing.timestamp_column is not None:
        base = np.asarray(frames.columns[timing.timestamp_column], dtype=np.float64).reshape(len(frames))
        if not np.isfinite(base).all():
            raise DatasetError(frames.episode.data_file, f"camera timestamp column {timing.timestamp_column!r} "
                               "has non-finite values")
        base_ns: IntArray = np.round(base * 1e9).astype(np.int64)
    else:
        base_ns = frames.stamp_ns
    out: IntArray = base_ns + round(timing.offset_s * 1e9)
    return out


def _world_edges(cfg: RobotConfig, model: RobotModel, state: FloatArray, names: Sequence[str], stamps: IntArray,
                 source: str) -> list[TransformTable]:
    """``world -> `` the mobile base per row (when it has one), and the arm's base on what it stands on (several
    arms: their bases hang from it in the model already)."""
    out = [] if cfg.mobile_base is None else [mobile_base_edge(cfg.mobile_base, cfg.world_frame, state, names,
                                                                 stamps, source)]
    if model.root != cfg.arms_frame:
        out.append(TransformTable.from_rows(
            cfg.arms_frame, model.root, [0], [cfg.world_from_base_translation], [cfg.world_from_base_quat_xyzw],
            is_static=True, source=f"{cfg.source}:world_from_base"))
    return out


def _joint_edges(
    model: RobotModel, cfg: RobotConfig, q: Mapping[str, FloatArray], stamps: IntArray, source: str
) -> list[TransformTable]:
    n = stamps.shape[0]
    given: dict[str, FloatArray] = dict(q)
    for name, value in cfg.hold.items():
        given[name] = np.full(n, value)
    local = model.joint_poses(given, default=0.0)
    dynamic = set(q)
    for joint in model.joints.values():
        if joint.mimic is not None and joint.mimic.joint in dynamic:
            dynamic.add(joint.name)
    out: list[TransformTable] = []
    for name, joint in model.joints.items():
        translation, quat = local[name]
        if name in dynamic:
            out.append(TransformTable.from_rows(joint.parent, joint.child, stamps, translation, quat,
                                                source=f"{source}->{name}"))
        else:  # fixed, held or left at zero: one timeless sample
            out.append(TransformTable.from_rows(joint.parent, joint.child, [0], translation[:1], quat[:1],
                                                is_static=True, source=f"{model.source}:{name}"))
    return out


def _mount_edges(cfg: RobotConfig) -> list[TransformTable]:
    out: list[TransformTable] = []
    for cam in cfg.cameras.values():
        for edge in cam.mount_edges():
            out.append(TransformTable.from_rows(edge.parent, edge.child, [0], [edge.xyz], [edge.quat_xyzw],
                                                is_static=True, source=cam.source))
    return out


def _joint_states(
    cfg: RobotConfig, q: Mapping[str, FloatArray], stamps: IntArray, source: str
) -> JointStateTable:
    parts: list[JointStateTable] = []
    n = stamps.shape[0]
    for m in cfg.joints:
        parts.append(JointStateTable(
            stamp_ns=stamps, log_time_ns=stamps, joint=np.full(n, m.joint), position=q[m.joint],
            velocity=np.full(n, np.nan), effort=np.full(n, np.nan), source=np.full(n, f"{source}[{m.state}]"),
        ))
    return JointStateTable.concat(parts)


def _video_file(frames: EpisodeFrames, key: str | None) -> str | None:
    path = frames.episode.video_files.get(key) if key is not None else None
    return None if path is None else str(path)


def _missing_video(frames: EpisodeFrames, key: str | None) -> str | None:
    path = frames.episode.missing_videos.get(key) if key is not None else None
    return None if path is None else str(path)


def missing_video_note(reader: DatasetReader, path: Path, key: str, episode: int, camera: str | None = None) -> str:
    """One line: the video info.json's ``video_path`` points to for ``key`` in ``episode`` is not on disk (whose frames
    are then left out: ``camera``'s, or the video's)."""
    whose = f"camera {camera}'s frames" if camera is not None else "its frames"
    return (f"{path}: missing: info.json's video_path {reader.video_path!r} with video_key {key} points here for "
            f"episode {episode}; {whose} are left out")


def scan_dataset(path: str | Path, episode: int | None = None, *, clocks: bool = False) -> LogInfo:
    """What a LeRobot dataset holds, from its metadata: features as topics, frames, fps, notes.

    With ``episode``, the counts and the span are that episode's, not the whole dataset's. With
    ``clocks``, a note per video says how its frames pair with the rows and why (of ``episode``, else of
    the first episode): frames against rows, the declared fps against the stamps' rate, the largest
    departure of the stamps from ``frame_index / fps``.
    """
    reader = DatasetReader(path)
    lengths = reader.lengths()
    if episode is not None:
        frames = longest = lengths.get(episode, 0)
    else:
        total = reader.info.get("total_frames")
        frames = int(total) if isinstance(total, int) else 0
        longest = max(lengths.values(), default=0)
    topics = tuple(
        TopicInfo(name=key, msgtype=f"lerobot/{feat.dtype}{list(feat.shape)}", count=frames, rate_hz=reader.fps,
                  encoding="video" if feat.is_video else "parquet")
        for key, feat in reader.features.items()
    )
    layout = "one episode per file" if reader.layout is Layout.V2 else "episodes share files"
    said = _clock_notes(reader, episode) if clocks else []
    return LogInfo(
        format="lerobot", path=Path(path), start_ns=0, end_ns=round(max(longest - 1, 0) / reader.fps * 1e9),
        topics=topics, notes=(*reader.notes, *said), message_count=frames,
        container=f"lerobot {reader.version} ({len(reader.episodes())} episodes, {layout}, {reader.fps:g} fps)",
    )


def _clock_notes(reader: DatasetReader, episode: int | None) -> list[str]:
    """One line per video of the episode (the first one when None): how its frames pair with the rows."""
    episodes = reader.episodes()
    if not episodes or not reader.video_keys:
        return []
    index = episodes[0] if episode is None else episode
    frames = reader.read(index)
    out = []
    for key in reader.video_keys:
        if key in frames.episode.missing_videos:
            out.append(missing_video_note(reader, frames.episode.missing_videos[key], key, index))
        if key not in frames.episode.video_files:
            continue
        line = episode_clock(key, frames, reader.fps).summary()
        out.append(line if episode is not None else f"{line} (episode {index})")
    return out


class LeRobotAdapter:
    """The :class:`framechain.adapters.LogAdapter` of LeRobot dataset directories.

    ``open(path, chain)`` takes the episode and the robot configuration from ``chain.robot``:
    ``{"episode": N, "config": "robot.yaml"}`` (or a :class:`RobotConfig`), or the robot.yaml keys inline
    plus ``episode``.
    Register it with ``framechain.adapters.register_adapter(LeRobotAdapter())``.
    """

    name = "lerobot"

    def probe(self, path: Path) -> bool:
        return is_lerobot_dataset(path)

    def scan(self, path: Path) -> LogInfo:
        return scan_dataset(path)

    def open(self, path: Path, chain: ChainConfig | None, *, progress: bool = False) -> LoadedLog:
        section = dict(chain.robot) if chain is not None and chain.robot else {}
        episode = section.pop("episode", None)
        if isinstance(episode, bool) or not isinstance(episode, int):
            raise AdapterError(path, "a LeRobot dataset needs an episode: chain robot section {episode: N, "
                               "config: robot.yaml} (framechain ... --episode N --robot robot.yaml)")
        config = section.pop("config", None)
        robot: RobotConfig | Path
        if isinstance(config, RobotConfig):  # made in memory (a known arm's generated robot.yaml)
            robot = config
        elif config is not None:
            robot = Path(str(config))
        elif "urdf" in section or "arms" in section:
            robot = RobotConfig.from_mapping(section, base_dir=Path.cwd(), source="chain robot section")
        else:
            raise AdapterError(path, "a LeRobot dataset needs a robot configuration: chain robot section "
                               "{episode: N, config: robot.yaml}")
        markers = chain.evidence.markers if chain is not None else None
        timeline = open_dataset(path, episode=episode, robot=robot, markers=markers)
        info = scan_dataset(path, episode).with_notes(list(timeline.metadata.get("notes", [])))
        decoded = {str(timeline.metadata["state_feature"]): "joint_state"}
        return LoadedLog(timeline=timeline, info=info, decoded_topics=decoded)
