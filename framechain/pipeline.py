"""One way in: read a log (any format) with its chain, replay it once, align its evidence once, attribute it.

:func:`run` is the run every command makes: parse -> ``run`` -> sinks. It reads the log once (a
suggested chain is worked out from the same read), replays once and aligns once, and hands a
:class:`~framechain.analysis.run.Run` to the sinks, which compute nothing a stage before them owns.
:func:`attribute_log` is ``run`` for its attribution: a pure function of its inputs with no global
state, so a fleet's episodes can be mapped over a process pool (or Ray) and the results gathered
into one table. :func:`load_log` is the reading part alone (with a chain suggested when none is
given); :func:`read_log` reads a robot log as it is (``framechain info`` and ``tf``).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any

from framechain import adapters
from framechain import suggest as suggestions
from framechain.adapters.messages.egomotion_frames import camera_motion_source, image_cameras
from framechain.analysis.egomotion.attribution import with_camera_motion
from framechain.analysis.egomotion.curves import rotation_rate_curves
from framechain.analysis.egomotion.run import CameraMotionEvidence, measure_cameras
from framechain.analysis.evidence.replayed import Replayed, replay_chain
from framechain.analysis.run import LoadedRun, NotAttributed, Run
from framechain.analysis.verdict.attribute import attribute_replayed
from framechain.analysis.verdict.findings import AnalysisError, Attribution, Unattributed
from framechain.config.chain import ChainConfig, ChainFrames
from framechain.errors import FramechainError
from framechain.progress import Progress
from framechain.replay import ReplayResult
from framechain.sinks.text import position_said
from framechain.timeline import LogInfo, Timeline

#: The path of a run made from a Timeline in memory rather than a file.
IN_MEMORY = Path("<timeline>")
#: File suffixes of logs among other files in a folder (a ROS 2 bag directory, a LeRobot dataset and a
#: saved timeline are recognised by their metadata files instead).
LOG_SUFFIXES = (".mcap", ".bag", ".db3")


def load_chain(chain: ChainConfig | str | Path | None) -> ChainConfig | None:
    if chain is None or isinstance(chain, ChainConfig):
        return chain
    return ChainConfig.from_yaml(chain)


def load_log(
    path: str | Path | Timeline,
    chain: ChainConfig | str | Path | None = None,
    *,
    episode: int | None = None,
    robot: str | Path | None = None,
    progress: bool | Progress = False,
    generated_robot_at: Path | None = None,
) -> LoadedRun:
    """Read MCAP, ROS 1 bag, ROS 2 bag, a LeRobot dataset or a saved Timeline directory, once.

    ``generated_robot_at``: where the command writes a robot.yaml made for a known arm (its fixes name that file).

    Without a chain the log is read with every topic framechain understands (and the point topics
    whose names say their evidence role), the chain is suggested from that read, and the read is
    narrowed to the suggestion's detections topic. A Timeline in memory is taken as it is.
    """
    config = load_chain(chain)
    if isinstance(path, Timeline):
        return _stored_chain(IN_MEMORY, path, config)
    target, found = _the_log_in(Path(path))
    if (target / "timeline.json").is_file():
        return _stored_chain(target, Timeline.load(target), config)
    if adapters.LeRobotAdapter().probe(target):
        return _load_lerobot(target, config, chain, episode=episode, robot=robot, generated_at=generated_robot_at)
    if episode is not None or robot is not None:
        raise FramechainError(f"{target}: --episode and --robot are for LeRobot datasets; this is not one")
    if config is not None:
        loaded = _with_notes(read_log(target, config, progress=progress), found)
        _check_frames(target, loaded.timeline, config, loaded.info)
        warnings = _disagreements(loaded, config)
        return LoadedRun(path=target, timeline=loaded.timeline, chain=config, info=loaded.info,
                         notes=(*warnings, *_named_typos(loaded.info, config)), warnings=warnings)
    loaded = _with_notes(read_log(target, None, progress=progress, point_roles=suggestions.evidence_roles), found)
    suggestion = suggestions.suggest(loaded)
    if suggestion.config.cameras:  # a rig calibrated by files beside the log: read through them
        loaded = read_log(target, suggestion.config, progress=progress)
    else:
        loaded = suggestions.as_suggested(loaded, suggestion.config)
    warnings = _disagreements(loaded, suggestion.config)
    return LoadedRun(path=target, timeline=loaded.timeline, chain=suggestion.config, chain_suggested=True,
                     info=loaded.info, notes=(*warnings, *loaded.info.notes, *_chain_beside(target)),
                     suggestion=suggestion, warnings=warnings)


def read_log(
    path: str | Path,
    chain: ChainConfig | None = None,
    *,
    progress: bool | Progress = False,
    kinds: Collection[str] | None = None,
    point_roles: Callable[[LogInfo], Mapping[str, str]] | None = None,
) -> adapters.LoadedLog:
    """Read a robot log (MCAP, ROS 1 bag, ROS 2 bag) into the model as it is: one pass over the topics
    ``chain`` needs (every topic framechain understands without one), narrowed to message ``kinds``
    (``framechain tf`` reads the frame tree alone). No chain is suggested (``framechain info`` shows
    the log whole). A folder of logs that is not itself a log holds one log, or it is an error that lists
    them."""
    target, found = _the_log_in(Path(path))
    return _with_notes(adapters.open_log(target, chain, progress=progress, kinds=kinds, point_roles=point_roles),
                       found)


def _logs_in_folder(folder: Path) -> tuple[list[Path], list[str]]:
    """The logs directly in ``folder`` (files with a log suffix, ROS 2 bag directories) and a note for each
    file framechain wrote (an exported MCAP holds a copy of a log: it is skipped, never taken for a log)."""
    logs: list[Path] = []
    skipped: list[str] = []
    try:
        children = sorted(folder.iterdir())
    except OSError as err:
        raise FramechainError(f"{folder}: cannot list the directory ({err.strerror})") from err
    for child in children:
        if child.name.startswith("."):
            continue
        if child.is_dir() and (child / "metadata.yaml").is_file():
            logs.append(child)
        elif child.is_file() and child.suffix.lower() in LOG_SUFFIXES:
            wrote = adapters.framechain_output(child)
            if wrote is None:
                logs.append(child)
            else:
                skipped.append(f"{child} skipped: written by {wrote}, not a recording")
    return logs, skipped


def _the_log_in(path: Path) -> tuple[Path, list[str]]:
    """The log ``path`` names, and notes on how it was found. A file, a ROS 2 bag, a LeRobot dataset or a saved
    timeline is itself; a folder of logs holding exactly one log (besides framechain's own outputs) is that
    log; a folder of several is an error that lists them and points to ``batch``."""
    if not path.exists():
        raise FramechainError(f"{path}: no such file or directory")
    if path.is_file():
        wrote = adapters.framechain_output(path)
        return path, [] if wrote is None else [
            f"{path.name} was written by {wrote}: it holds a copy of that log and framechain's annotations"]
    is_log = ((path / "metadata.yaml").is_file() or (path / "timeline.json").is_file()
              or adapters.LeRobotAdapter().probe(path))
    if is_log:
        return path, []
    logs, skipped = _logs_in_folder(path)
    if len(logs) == 1:
        return logs[0], [f"{path} is a folder, not a log; read its only log {logs[0].name}", *skipped]
    if len(logs) > 1:
        shown = ", ".join(p.name for p in logs[:6]) + (f" and {len(logs) - 6} more" if len(logs) > 6 else "")
        raise FramechainError(f"{path}: a folder of {len(logs)} logs ({shown}), not one log: name one of them, or "
                              f"run `framechain batch {path} --out DIR` to analyse them all")
    return path, skipped  # no log in it: the reader says what it is not


def _disagreements(loaded: adapters.LoadedLog, chain: ChainConfig) -> tuple[str, ...]:
    """What to say before any finding: a calibration of another topic's camera, and detections of the chain's
    topic stamped with another camera's frame."""
    topic = chain.topics.detections
    stamped = [n for n in suggestions.frame_id_disagreements(loaded) if topic and n.startswith(f"topic {topic}:")]
    return (*suggestions.calibration_disagreements(chain, loaded.info), *stamped)


def _with_notes(loaded: adapters.LoadedLog, notes: list[str]) -> adapters.LoadedLog:
    return replace(loaded, info=loaded.info.with_notes(notes)) if notes else loaded


def _chain_beside(log: Path) -> list[str]:
    """Without --chain, a chain file beside the log is not used silently: a note names it."""
    beside = suggestions.chain_files_beside(log)
    if not beside:
        return []
    return [f"{beside[0]} lies beside the log but no --chain was given: the chain was suggested (pass --chain "
            f"{beside[0]} to use it; `framechain batch` does)"]


def _named_typos(info: LogInfo, chain: ChainConfig) -> list[str]:
    """The reader's notes, a topic the chain names but the log lacks followed by what it may have meant."""
    close = {m.topic: m.close for m in suggestions.missing_topics(info, chain) if m.close}
    out = []
    for note in info.notes:
        out.append(note)
        topic = note.removeprefix("topic ").split(": named by the chain as ", 1)[0]
        if note.startswith("topic ") and ": named by the chain as " in note and topic in close:
            out.append(f"topic {topic}: did you mean {suggestions.or_list(close[topic])}?")
    return out


def _stored_chain(target: Path, timeline: Timeline, config: ChainConfig | None) -> LoadedRun:
    """A saved (or in-memory) timeline, with the chain given or the one stored in its metadata."""
    stored = timeline.metadata.get("chain")
    if config is None and not isinstance(stored, dict):
        raise FramechainError(f"{target}: a saved timeline without a chain needs --chain CHAIN.yaml")
    chosen = config or ChainConfig.from_dict(stored, where=f"{target}/timeline.json")  # type: ignore[arg-type]
    if config is not None:
        _check_frames(target, timeline, config)
    return LoadedRun(path=target, timeline=timeline, chain=chosen, chain_suggested=config is None)


#: The chain keys whose topics give each frame of the chain its edges (or its name, for the camera).
_FRAME_SOURCES = {"camera": ("topics.detections", "topics.camera_info", "topics.pixel_points"),
                  "body": ("topics.odometry",), "world": ("topics.odometry",)}


def _check_frames(target: Path, timeline: Timeline, chain: ChainConfig, info: LogInfo | None = None) -> None:
    """A frame the chain names but no transform mentions is a typo, not a missing edge 235 times; when a topic
    the chain names for that frame is not in the log, the topic is the typo."""
    transforms = timeline.transforms
    if not len(transforms):
        return  # said elsewhere, with the counts
    known = set(transforms.parent.tolist()) | set(transforms.child.tolist())
    missing = suggestions.missing_topics(info, chain)
    named = [(role, getattr(chain.frames, role)) for role in ("camera", "body", "world")]
    named += [("camera", frame) for frame in chain.camera_frames()[1:]]  # a rig's other cameras
    for role, name in named:
        if name in known:
            continue
        cause = next((m for m in missing if m.key in _FRAME_SOURCES[role]), None)
        if cause is not None:
            raise FramechainError(f"{target}: {cause.line()} (without it the chain's {role} frame {name!r} is in no "
                                  "transform of the log)")
        close = suggestions.did_you_mean(name, known)
        hint = f"; did you mean {suggestions.or_list(close)}?" if close else ""
        if role == "world" and name == ChainFrames().world and not close:  # the default, perhaps never written
            hint = (f" ({name!r} is frames.world's default: name the log's world frame, or set world equal to body "
                    f"({chain.frames.body}) for a body that does not move)")
        raise FramechainError(f"{target}: the chain's {role} frame {name!r} is in no transform of the log{hint}")


def _load_lerobot(
    target: Path, config: ChainConfig | None, chain_arg: ChainConfig | str | Path | None, *,
    episode: int | None, robot: str | Path | None, generated_at: Path | None = None,
) -> LoadedRun:
    """A LeRobot episode: the robot section comes from --episode/--robot or the chain's ``robot:``."""
    section: dict[str, Any] = dict(config.robot) if config is not None and config.robot else {}
    if episode is not None:
        section["episode"] = episode
    if robot is not None:
        _check_not_urdf(Path(robot))
        section["config"] = str(Path(robot).resolve())
    elif "config" in section and isinstance(chain_arg, str | Path):
        # robot.yaml named in CHAIN.yaml resolves against the CHAIN.yaml's folder.
        section["config"] = str((Path(chain_arg).resolve().parent / str(section["config"])).resolve())
    generated = None
    if "episode" not in section or not _ROBOT_KEYS & set(section):
        # What is missing, asked for at once; a known arm's robot.yaml needs neither.
        generated = (suggestions.generated_robot(target, section.get("episode")) if not _ROBOT_KEYS & set(section)
                     else None)
        if generated is None:
            raise FramechainError(suggestions.dataset_needs(target, episode=section.get("episode"),
                                                         robot_given=bool(_ROBOT_KEYS & set(section))))
        section.update(generated.mapping(), episode=generated.episode)
    given = ({"episode": section["episode"], "config": generated.config(generated_at)} if generated is not None
             else section)
    loaded = adapters.open_log(target, replace(config or ChainConfig(), robot=given))
    suggested = config is None
    if config is not None:
        _check_frames(target, loaded.timeline, config, loaded.info)
    else:
        stored = loaded.timeline.metadata.get("chain")
        if not isinstance(stored, dict):
            raise FramechainError(f"{target}: give --chain CHAIN.yaml to name the camera, body and world frames")
        config = ChainConfig.from_dict(stored, where=f"{target} (suggested by robot.yaml)")
    notes = [f"no --robot given: {generated.line}"] if generated is not None else []
    return LoadedRun(path=target, timeline=loaded.timeline, chain=replace(config, robot=section),
                     chain_suggested=suggested, info=loaded.info, notes=(*notes, *loaded.info.notes),
                     generated_robot=generated)


#: Keys of a chain's robot section that give the robot: robot.yaml's path, or its keys inline.
_ROBOT_KEYS = {"config", "urdf", "arms"}


def _check_not_urdf(robot: Path) -> None:
    """A URDF given where robot.yaml is expected: say what robot.yaml is, in one line."""
    try:
        with robot.open("rb") as f:
            head = f.read(512).lstrip()
    except OSError:
        return  # RobotConfig.load says the file cannot be read
    if robot.suffix.lower() in (".urdf", ".xacro", ".xml") or head.startswith(b"<"):
        raise FramechainError(
            f"--robot {robot}: a URDF; --robot takes a robot.yaml that names it (urdf: {robot.name}) and maps "
            "the dataset's joint states to its joints and the cameras to their links (see "
            "docs/lerobot.md#the-robot-file)")


def run(
    log: str | Path | Timeline,
    chain: ChainConfig | str | Path | None = None,
    *,
    episode: int | None = None,
    robot: str | Path | None = None,
    attribute: bool = True,
    seed: int = 0,
    bootstrap: int = 30,
    progress: Progress | None = None,
    warn: Callable[[str], None] | None = None,
    when_read: Callable[[], None] | None = None,
    generated_robot_at: Path | None = None,
) -> Run:
    """Read ``log`` once, replay it once through ``chain`` (suggested when None), align its evidence once
    and attribute its error (unless ``attribute`` is False): a :class:`Run`. ``warn`` hears, as soon as the
    log is read and before any fit, what disagrees (a calibration of another camera's topic);
    ``when_read`` is called then too (a command starts its report's renderers on the core the read
    leaves idle); ``generated_robot_at``: as for :func:`load_log`.

    A log that cannot be attributed is still a run: ``run.not_attributed`` says why, and when no
    observation replayed ``run.nothing_replayed`` says which chain key to add. A log that cannot be
    read, or a chain that does not fit it, raises :class:`FramechainError` (one line).
    """
    loaded = load_log(log, chain, episode=episode, robot=robot, progress=progress or False,
                      generated_robot_at=generated_robot_at)
    if warn is not None:
        for warning in loaded.warnings:
            warn(warning)
    if when_read is not None:
        when_read()
    if progress is not None:
        progress(f"replaying {len(loaded.timeline.observations):,} observations")
    # A bearing-only static target is replayed as rays when attributed (decided here, before the replay).
    replayed = replay_chain(loaded.timeline, loaded.chain, rays=attribute)
    nothing = _why_nothing_replayed(loaded, replayed.replay)
    if not attribute:
        not_asked = NotAttributed(Unattributed.NOT_ASKED, "attribution was not asked for")
        return Run(loaded=loaded, replayed=replayed, not_attributed=not_asked, nothing_replayed=nothing)
    attribution, why, motion = _attributed(loaded, replayed, nothing, seed=seed, bootstrap=bootstrap,
                                           progress=progress)
    if attribution is not None and loaded.generated_robot is not None:
        attribution = replace(attribution, notes=(*attribution.notes, *_placeholder_mounts(attribution)))
    return Run(loaded=loaded, replayed=replayed, attribution=attribution, not_attributed=why,
               nothing_replayed=nothing, camera_motion=motion, rotation_rates=rotation_rate_curves(motion))


def _placeholder_mounts(attribution: Attribution) -> list[str]:
    """Why a camera of a known arm run without robot.yaml may be unexplained: its mount is a placeholder at its
    link's origin. The measurement takes the translation forward kinematics gives the camera's centre; one a few
    centimetres off moves along another direction (generated SO-101 episodes, the camera 6 cm from gripper_link:
    17 deg/s of misfit left where its true position leaves 2), so the position must be measured."""
    return [f"camera {e['camera']}: its mount in the generated robot.yaml is a placeholder at the origin of "
            f"{e['declared_link']}; a camera a few centimetres from there moves along another "
            f"direction than forward kinematics gives, and its motion is then not explained{_position_said(e)}: "
            f"measure the camera's position on its link (cameras.{e.get('name') or 'NAME'}.mount.xyz, metres) and "
            "pass --robot"
            for e in attribution.camera_motion if e.get("explained") is False]


def _position_said(entry: Mapping[str, Any]) -> str:
    """What became of a camera's position fitted from its images, for a note on why it is still unexplained."""
    said = position_said(entry)
    if not said:
        return " (its images did not determine its position: see its note)"
    return f" (the position fitted from its images, {said}, did not explain it either)"


def _attributed(
    loaded: LoadedRun, replayed: Replayed, nothing: str | None, *, seed: int, bootstrap: int,
    progress: Progress | None,
) -> tuple[Attribution | None, NotAttributed | None, CameraMotionEvidence | None]:
    """The replay attributed, with the cameras' own motion where it is measured: the attribution (None: it could
    not be made), why not, and the motion."""
    attribution: Attribution | None = None
    why: NotAttributed | None = None
    try:
        attribution = attribute_replayed(replayed, loaded.chain, seed=seed, bootstrap=bootstrap, progress=progress)
    except AnalysisError as err:
        why = NotAttributed(err.reason, _unattributed_line(loaded, err, nothing))
    motion = None
    if _measures_camera_motion(loaded, attribution):
        cameras = image_cameras(loaded.timeline)
        # A robot.yaml framechain generated guesses each camera's lens and puts it at its link's origin.
        motion = measure_cameras(loaded.chain, replayed.buffer, cameras, partial(camera_motion_source, loaded.timeline),
                                 progress=progress, guessed=cameras if loaded.generated_robot else ())
    if motion is not None and (why is None or any(c.fit is not None for c in motion.cameras)):
        # A camera that moves is measured: evidence whatever else the log lacks.
        unattributed = () if why is None or why.reason is Unattributed.NO_DETECTIONS else (why.detail,)
        attribution, why = with_camera_motion(replayed, loaded.chain, attribution, motion, seed=seed), None
        attribution = replace(attribution, notes=(*unattributed, *attribution.notes))
    elif motion is not None and why is not None:  # only fixed cameras: they cannot stand in for detections
        why = NotAttributed(why.reason, "; ".join([why.detail, *(c.why_not for c in motion.cameras)]))
    if attribution is not None:
        attribution = _as_read(loaded, attribution)
    return attribution, why, motion


def _measures_camera_motion(loaded: LoadedRun, attribution: Attribution | None) -> bool:
    """Whether the cameras' own motion is measured: always for a LeRobot episode (the evidence of an episode as
    recorded, joints and video; beside markers, their corroboration), and for a robot log only when nothing
    else measures the chain (it costs seconds per camera, and images that do not move with the robot, such as a
    screen, would be read as a camera on the wrong link)."""
    if loaded.info is not None and loaded.info.format == "lerobot":
        return True
    return attribution is None or attribution.metric == "none"


def attribute_log(
    path: str | Path,
    chain: ChainConfig | str | Path | None = None,
    *,
    seed: int = 0,
    bootstrap: int = 30,
    episode: int | None = None,
    robot: str | Path | None = None,
    progress: Progress | None = None,
) -> tuple[Run, Attribution]:
    """Read, replay and attribute one log: ``(run, attribution)``; raises :class:`AnalysisError` (one line
    naming the log and why) when it cannot be attributed."""
    made = run(path, chain, episode=episode, robot=robot, seed=seed, bootstrap=bootstrap, progress=progress)
    return made, made.attributed()


def _why_nothing_replayed(loaded: LoadedRun, result: ReplayResult) -> str | None:
    """One line saying why no observation was replayed and which chain key to add (None: some were)."""
    nothing = result.nothing_replayed()
    if nothing is None:
        return None
    # A saved timeline has no LogInfo: the suggestions read what there is (their reading of a log's info
    # allows for none).
    log = adapters.LoadedLog(timeline=loaded.timeline, info=loaded.info, decoded_topics={})  # type: ignore[arg-type]
    why = suggestions.why_nothing_replayed(log, loaded.chain, nothing)
    # What the reader noticed on the chain's topics (an undecodable topic) often is the cause; a topic the line
    # already says the log lacks is not said twice.
    why += "".join(f"; {n}" for n in loaded.chain_topic_notes()
                   if not ((": named by the chain as " in n or ": did you mean " in n)
                           and n.split(": ", 1)[0].removeprefix("topic ") in why))
    if loaded.chain_suggested:
        why += " (the chain was suggested: `framechain info LOG` lists what the log lacks)"
    return why


def _unattributed_line(loaded: LoadedRun, err: AnalysisError, nothing: str | None) -> str:
    """Why the attribution could not be made, in one line (without the log's path)."""
    if err.reason is Unattributed.STATIC_TARGET:  # observations were replayed, too few per object
        return str(err)
    if nothing is not None:  # nothing replayed: say why and which key to add
        return nothing
    # Otherwise what the reader noticed (an undecodable topic) often explains it.
    return str(err) + "".join(f"; {n}" for n in loaded.chain_topic_notes())


def _as_read(loaded: LoadedRun, result: Attribution) -> Attribution:
    """What the reader noticed (a topic the chain names but the log lacks, undecodable messages) travels
    with the result into every output, and the source names the log read."""
    result = replace(result, notes=(*loaded.notes, *(n for n in result.notes if n not in loaded.notes)))
    if loaded.path == IN_MEMORY:
        return result
    source = dict(result.source)
    source.setdefault("path", str(loaded.path))
    if loaded.info is not None:
        source["path"] = str(loaded.path)
        source["format"] = loaded.info.format
    return replace(result, source=source)


__all__ = ["IN_MEMORY", "LoadedRun", "Run", "attribute_log", "load_chain", "load_log", "read_log", "run"]
