"""One way in: load a log (any format) with its chain, and attribute it.

``attribute_log(path, chain)`` is a pure function of its inputs with no global state, so a
fleet's episodes can be mapped over a process pool (or Ray) and the results gathered into one
table. Every command of the CLI loads through :func:`load_log`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import astuple, dataclass, field, replace
from pathlib import Path
from typing import Any

from framechain.analysis.attribute import AnalysisError, Attribution, attribute
from framechain.analysis.static import StaticTargetError
from framechain.config.chain import ChainConfig
from framechain.timeline import FramechainError, Timeline


@dataclass(frozen=True)
class LoadedRun:
    """A log in the model, with the chain to replay it through."""

    path: Path
    timeline: Timeline
    chain: ChainConfig
    chain_suggested: bool  # True when no --chain was given and the configuration was suggested
    info: Any = None  # the adapter's LogInfo (topics, span, notes) when read from a robot log
    notes: list[str] = field(default_factory=list)
    #: The suggestion (placeholders, what the log lacks) when no chain was given; None otherwise.
    suggestion: Any = None

    def why_nothing_replayed(self, counts: dict[str, Any]) -> str | None:
        """One line saying why no observation was replayed and which chain key to add (None: some were)."""
        from framechain import adapters

        if int(counts.get("replayed", 0)):
            return None
        loaded = adapters.LoadedLog(timeline=self.timeline, info=self.info, decoded_topics={})
        why = adapters.why_nothing_replayed(loaded, self.chain, counts)
        if why is None:
            return None
        # What the reader noticed on the chain's topics (an undecodable topic) often is the cause.
        why += "".join(f"; {n}" for n in self.chain_topic_notes())
        if self.chain_suggested:
            why += " (the chain was suggested: `framechain info LOG` lists what the log lacks)"
        return why

    def chain_topic_notes(self) -> list[str]:
        """The reader's notes on the topics the chain names (an undecodable topic, say)."""
        named = [t for t in astuple(self.chain.topics) if isinstance(t, str) and t]
        return [n for n in self.notes if any(n.startswith(f"topic {t}:") for t in named)]


def load_chain(chain: ChainConfig | str | Path | None) -> ChainConfig | None:
    if chain is None or isinstance(chain, ChainConfig):
        return chain
    return ChainConfig.from_yaml(chain)


def load_log(
    path: str | Path,
    chain: ChainConfig | str | Path | None = None,
    *,
    episode: int | None = None,
    robot: str | Path | None = None,
    progress: bool = False,
) -> LoadedRun:
    """Read MCAP, ROS 1 bag, ROS 2 bag, a LeRobot dataset or a saved Timeline directory."""
    from framechain import adapters

    target = Path(path)
    config = load_chain(chain)
    if not target.exists():
        raise FramechainError(f"{target}: no such file or directory")
    if (target / "timeline.json").is_file():
        timeline = Timeline.load(target)
        stored = timeline.metadata.get("chain")
        if config is None and not isinstance(stored, dict):
            raise FramechainError(f"{target}: a saved timeline without a chain needs --chain CHAIN.yaml")
        chosen = config or ChainConfig.from_dict(stored, where=f"{target}/timeline.json")  # type: ignore[arg-type]
        if config is not None:
            _check_frames(target, timeline, config)
        return LoadedRun(path=target, timeline=timeline, chain=chosen, chain_suggested=config is None)
    if adapters.LeRobotAdapter().probe(target):
        return _load_lerobot(target, config, chain, episode=episode, robot=robot)
    if episode is not None or robot is not None:
        raise FramechainError(f"{target}: --episode and --robot are for LeRobot datasets; this is not one")
    loaded = adapters.open_log(target, config, progress=progress)
    suggested = config is None
    suggestion = None
    if config is not None:
        _check_frames(target, loaded.timeline, config)
    else:
        suggestion = adapters.suggest(loaded)
        config = suggestion.config
        # Read again with the suggestion when it gives evidence topics a role, or picks one of several
        # detection topics (the others' detections are not this chain's to replay).
        sources = set(loaded.timeline.observations.source.tolist())
        if config.evidence_topics() or len(sources) > 1:
            loaded = adapters.open_log(target, config, progress=progress)
    return LoadedRun(path=target, timeline=loaded.timeline, chain=config, chain_suggested=suggested,
                     info=loaded.info, notes=list(getattr(loaded.info, "notes", [])), suggestion=suggestion)


def _check_frames(target: Path, timeline: Timeline, chain: ChainConfig) -> None:
    """A frame the chain names but no transform mentions is a typo, not a missing edge 235 times."""
    import difflib

    transforms = timeline.transforms
    if not len(transforms):
        return  # said elsewhere, with the counts
    known = set(transforms.parent.tolist()) | set(transforms.child.tolist())
    for role in ("camera", "body", "world"):
        name = getattr(chain.frames, role)
        if name not in known:
            close = difflib.get_close_matches(name, sorted(known), n=3)
            hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
            raise FramechainError(f"{target}: the chain's {role} frame {name!r} is in no transform of the log{hint}")


def _load_lerobot(
    target: Path, config: ChainConfig | None, chain_arg: ChainConfig | str | Path | None, *,
    episode: int | None, robot: str | Path | None,
) -> LoadedRun:
    """A LeRobot episode: the robot section comes from --episode/--robot or the chain's ``robot:``."""
    from framechain import adapters

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


def attribute_log(
    path: str | Path,
    chain: ChainConfig | str | Path | None = None,
    *,
    seed: int = 0,
    bootstrap: int = 30,
    episode: int | None = None,
    robot: str | Path | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[LoadedRun, Attribution]:
    """Load and attribute one log: ``(run, attribution)``."""
    run = load_log(path, chain, episode=episode, robot=robot, progress=progress is not None)
    try:
        result = attribute(run.timeline, run.chain, seed=seed, bootstrap=bootstrap, progress=progress)
    except AnalysisError as err:
        if isinstance(err.__cause__, StaticTargetError):  # observations were replayed, too few per object
            raise AnalysisError(f"{run.path}: {err}") from err
        # Nothing replayed: say why and which key to add; otherwise what the reader noticed (an
        # undecodable topic) often explains it.
        from framechain.replay import replay

        counts = replay(run.timeline, run.chain.frames, latency_budget_s=run.chain.latency_budget_s,
                        ignore_labels=run.chain.evidence.ignore_labels).counts()
        reason = run.why_nothing_replayed(counts)
        if reason is not None:
            raise AnalysisError(f"{run.path}: {reason}") from err
        raise AnalysisError(f"{run.path}: {err}" + "".join(f"; {n}" for n in run.chain_topic_notes())) from err
    # What the reader noticed (a topic the chain names but the log lacks, undecodable messages)
    # travels with the result into every output.
    result = replace(result, notes=(*run.notes, *(n for n in result.notes if n not in run.notes)))
    source = dict(result.source)
    source.setdefault("path", str(run.path))
    if run.info is not None:
        source["path"] = str(run.path)
        source["format"] = getattr(run.info, "format", source.get("format", "unknown"))
    return run, replace(result, source=source)
