"""One way in: load a log (any format) with its chain, and attribute it.

``attribute_log(path, chain)`` is a pure function of its inputs with no global state, so a
fleet's episodes can be mapped over a process pool (or Ray) and the results gathered into one
table. Every command of the CLI loads through :func:`load_log`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from framechain.analysis.attribute import Attribution, attribute
from framechain.timeline import ChainConfig, FramechainError, Timeline


@dataclass(frozen=True)
class LoadedRun:
    """A log in the model, with the chain to replay it through."""

    path: Path
    timeline: Timeline
    chain: ChainConfig
    chain_suggested: bool  # True when no --chain was given and the configuration was suggested
    info: Any = None  # the adapter's LogInfo (topics, span, notes) when read from a robot log
    notes: list[str] = field(default_factory=list)


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
        suggested = config is None
        if config is None:
            if not isinstance(stored, dict):
                raise FramechainError(f"{target}: a saved timeline without a chain needs --chain CHAIN.yaml")
            config = ChainConfig.from_dict(stored, where=f"{target}/timeline.json")
        return LoadedRun(path=target, timeline=timeline, chain=config, chain_suggested=suggested)
    if (target / "meta" / "info.json").is_file():
        from framechain.adapters.lerobot import open_dataset

        if episode is None:
            raise FramechainError(f"{target}: a LeRobot dataset needs --episode N")
        robot_config = robot or (config.robot.get("config") if config and config.robot else None)
        if robot_config is None:
            raise FramechainError(f"{target}: a LeRobot dataset needs --robot robot.yaml (URDF, joints, cameras)")
        timeline = open_dataset(target, episode=episode, robot=Path(str(robot_config)))
        stored = timeline.metadata.get("chain")
        if config is None and isinstance(stored, dict):
            return LoadedRun(target, timeline, ChainConfig.from_dict(stored), chain_suggested=True)
        if config is None:
            raise FramechainError(f"{target}: give --chain CHAIN.yaml to name the camera, body and world frames")
        return LoadedRun(target, timeline, config, chain_suggested=False)
    loaded = adapters.open_log(target, config, progress=progress)
    suggested = config is None
    if config is None:
        config = adapters.suggest_chain(loaded)
    return LoadedRun(
        path=target,
        timeline=loaded.timeline,
        chain=config,
        chain_suggested=suggested,
        info=loaded.info,
        notes=list(getattr(loaded.info, "notes", [])),
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
) -> tuple[LoadedRun, Attribution]:
    """Load and attribute one log: ``(run, attribution)``."""
    run = load_log(path, chain, episode=episode, robot=robot, progress=progress is not None)
    result = attribute(run.timeline, run.chain, seed=seed, bootstrap=bootstrap, progress=progress)
    source = dict(result.source)
    source.setdefault("path", str(run.path))
    if run.info is not None:
        source["path"] = str(run.path)
        source["format"] = getattr(run.info, "format", source.get("format", "unknown"))
    return run, replace(result, source=source)
