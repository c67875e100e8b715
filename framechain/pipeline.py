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
from dataclasses import astuple, dataclass, field, replace
from pathlib import Path
from typing import Any

from framechain import adapters
from framechain.analysis.attribute import attribute_replayed
from framechain.analysis.findings import AnalysisError, Attribution, Unattributed
from framechain.analysis.replayed import replay_chain
from framechain.analysis.run import NotAttributed, Run
from framechain.config.chain import ChainConfig
from framechain.replay import ReplayResult
from framechain.timeline import FramechainError, Timeline

#: The path of a run made from a Timeline in memory rather than a file.
IN_MEMORY = Path("<timeline>")


@dataclass(frozen=True)
class LoadedRun:
    """A log in the model, with the chain to replay it through (the reading part of a :class:`Run`)."""

    path: Path
    timeline: Timeline
    chain: ChainConfig
    chain_suggested: bool  # True when no --chain was given and the configuration was suggested
    info: Any = None  # the adapter's LogInfo (topics, span, notes) when read from a robot log
    notes: list[str] = field(default_factory=list)
    #: The suggestion (placeholders, what the log lacks) when no chain was given; None otherwise.
    suggestion: Any = None

    def chain_topic_notes(self) -> list[str]:
        """The reader's notes on the topics the chain names (an undecodable topic, say)."""
        named = [t for t in astuple(self.chain.topics) if isinstance(t, str) and t]
        return [n for n in self.notes if any(n.startswith(f"topic {t}:") for t in named)]


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
    progress: bool = False,
) -> LoadedRun:
    """Read MCAP, ROS 1 bag, ROS 2 bag, a LeRobot dataset or a saved Timeline directory, once.

    Without a chain the log is read with every topic framechain understands (and the point topics
    whose names say their evidence role), the chain is suggested from that read, and the read is
    narrowed to the suggestion's detections topic. A Timeline in memory is taken as it is.
    """
    config = load_chain(chain)
    if isinstance(path, Timeline):
        return _stored_chain(IN_MEMORY, path, config)
    target = Path(path)
    if not target.exists():
        raise FramechainError(f"{target}: no such file or directory")
    if (target / "timeline.json").is_file():
        return _stored_chain(target, Timeline.load(target), config)
    if adapters.LeRobotAdapter().probe(target):
        return _load_lerobot(target, config, chain, episode=episode, robot=robot)
    if episode is not None or robot is not None:
        raise FramechainError(f"{target}: --episode and --robot are for LeRobot datasets; this is not one")
    if config is not None:
        loaded = read_log(target, config, progress=progress)
        _check_frames(target, loaded.timeline, config)
        return LoadedRun(path=target, timeline=loaded.timeline, chain=config, chain_suggested=False,
                         info=loaded.info, notes=list(loaded.info.notes))
    loaded = read_log(target, None, progress=progress, point_roles=adapters.evidence_roles)
    suggestion = adapters.suggest(loaded)
    if suggestion.config.cameras:  # a rig calibrated by files beside the log: read through them
        loaded = read_log(target, suggestion.config, progress=progress)
    else:
        loaded = adapters.as_suggested(loaded, suggestion.config)
    return LoadedRun(path=target, timeline=loaded.timeline, chain=suggestion.config, chain_suggested=True,
                     info=loaded.info, notes=list(loaded.info.notes), suggestion=suggestion)


def read_log(
    path: str | Path,
    chain: ChainConfig | None = None,
    *,
    progress: bool = False,
    kinds: Collection[str] | None = None,
    point_roles: Callable[[adapters.LogInfo], Mapping[str, str]] | None = None,
) -> adapters.LoadedLog:
    """Read a robot log (MCAP, ROS 1 bag, ROS 2 bag) into the model as it is: one pass over the topics
    ``chain`` needs (every topic framechain understands without one), narrowed to message ``kinds``
    (``framechain tf`` reads the frame tree alone). No chain is suggested (``framechain info`` shows
    the log whole)."""
    return adapters.open_log(path, chain, progress=progress, kinds=kinds, point_roles=point_roles)


def _stored_chain(target: Path, timeline: Timeline, config: ChainConfig | None) -> LoadedRun:
    """A saved (or in-memory) timeline, with the chain given or the one stored in its metadata."""
    stored = timeline.metadata.get("chain")
    if config is None and not isinstance(stored, dict):
        raise FramechainError(f"{target}: a saved timeline without a chain needs --chain CHAIN.yaml")
    chosen = config or ChainConfig.from_dict(stored, where=f"{target}/timeline.json")  # type: ignore[arg-type]
    if config is not None:
        _check_frames(target, timeline, config)
    return LoadedRun(path=target, timeline=timeline, chain=chosen, chain_suggested=config is None)


def _check_frames(target: Path, timeline: Timeline, chain: ChainConfig) -> None:
    """A frame the chain names but no transform mentions is a typo, not a missing edge 235 times."""
    import difflib

    transforms = timeline.transforms
    if not len(transforms):
        return  # said elsewhere, with the counts
    known = set(transforms.parent.tolist()) | set(transforms.child.tolist())
    named = [(role, getattr(chain.frames, role)) for role in ("camera", "body", "world")]
    named += [("camera", frame) for frame in chain.camera_frames()[1:]]  # a rig's other cameras
    for role, name in named:
        if name not in known:
            close = difflib.get_close_matches(name, sorted(known), n=3)
            hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
            raise FramechainError(f"{target}: the chain's {role} frame {name!r} is in no transform of the log{hint}")


def _load_lerobot(
    target: Path, config: ChainConfig | None, chain_arg: ChainConfig | str | Path | None, *,
    episode: int | None, robot: str | Path | None,
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
    if "episode" not in section:
        raise FramechainError(f"{target}: a LeRobot dataset needs --episode N")
    if "config" not in section and "urdf" not in section:
        raise FramechainError(f"{target}: a LeRobot dataset needs --robot robot.yaml (URDF, joints, cameras)")
    loaded = adapters.open_log(target, replace(config or ChainConfig(), robot=section))
    suggested = config is None
    if config is not None:
        _check_frames(target, loaded.timeline, config)
    else:
        stored = loaded.timeline.metadata.get("chain")
        if not isinstance(stored, dict):
            raise FramechainError(f"{target}: give --chain CHAIN.yaml to name the camera, body and world frames")
        config = ChainConfig.from_dict(stored, where=f"{target} (suggested by robot.yaml)")
    return LoadedRun(path=target, timeline=loaded.timeline, chain=replace(config, robot=section),
                     chain_suggested=suggested, info=loaded.info, notes=list(loaded.info.notes))


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
            "the dataset's joint states to its joints and the cameras to their links (README: 'LeRobot "
            "datasets: robot.yaml')")


def run(
    log: str | Path | Timeline,
    chain: ChainConfig | str | Path | None = None,
    *,
    episode: int | None = None,
    robot: str | Path | None = None,
    attribute: bool = True,
    seed: int = 0,
    bootstrap: int = 30,
    progress: Callable[[str], None] | None = None,
) -> Run:
    """Read ``log`` once, replay it once through ``chain`` (suggested when None), align its evidence once
    and attribute its error (unless ``attribute`` is False): a :class:`Run`.

    A log that cannot be attributed is still a run: ``run.not_attributed`` says why, and when no
    observation replayed ``run.nothing_replayed`` says which chain key to add. A log that cannot be
    read, or a chain that does not fit it, raises :class:`FramechainError` (one line).
    """
    loaded = load_log(log, chain, episode=episode, robot=robot, progress=progress is not None)
    if progress is not None:
        progress("replaying observations")
    # A bearing-only static target is replayed as rays when attributed (decided here, before the replay).
    replayed = replay_chain(loaded.timeline, loaded.chain, rays=attribute)
    nothing = _why_nothing_replayed(loaded, replayed.replay)
    attribution: Attribution | None = None
    why: NotAttributed | None = NotAttributed(Unattributed.NOT_ASKED, "attribution was not asked for")
    if attribute:
        try:
            attribution = _as_read(loaded, attribute_replayed(replayed, loaded.chain, seed=seed, bootstrap=bootstrap,
                                                              progress=progress))
            why = None
        except AnalysisError as err:
            why = NotAttributed(err.reason, _unattributed_line(loaded, err, nothing))
    return Run(
        path=loaded.path, timeline=loaded.timeline, chain=loaded.chain, buffer=replayed.buffer,
        replay=replayed.replay, aligned=replayed.aligned, attribution=attribution, not_attributed=why,
        nothing_replayed=nothing, chain_suggested=loaded.chain_suggested, suggestion=loaded.suggestion,
        info=loaded.info, notes=tuple(loaded.notes),
    )


def attribute_log(
    path: str | Path,
    chain: ChainConfig | str | Path | None = None,
    *,
    seed: int = 0,
    bootstrap: int = 30,
    episode: int | None = None,
    robot: str | Path | None = None,
    progress: Callable[[str], None] | None = None,
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
    log = adapters.LoadedLog(timeline=loaded.timeline, info=loaded.info, decoded_topics={})
    why = adapters.why_nothing_replayed(log, loaded.chain, nothing)
    # What the reader noticed on the chain's topics (an undecodable topic) often is the cause.
    why += "".join(f"; {n}" for n in loaded.chain_topic_notes())
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
        source["format"] = getattr(loaded.info, "format", source.get("format", "unknown"))
    return replace(result, source=source)


__all__ = ["IN_MEMORY", "LoadedRun", "Run", "attribute_log", "load_chain", "load_log", "read_log", "run"]
