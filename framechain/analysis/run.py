"""One run: a log read, replayed, aligned and attributed, each stage computed once and handed down.

The stages, each holding what it was made from:

1. :class:`LoadedRun`: the log in the model with the chain to replay it through (and how both came:
   the reader's :class:`~framechain.timeline.LogInfo`, a suggested chain, a generated robot.yaml);
2. :class:`~framechain.analysis.evidence.replayed.Replayed`: that timeline replayed once through the
   chain, its logged evidence aligned once;
3. :class:`Run`: both, with the attribution (or why there is none) and the cameras' own motion.

:func:`framechain.pipeline.run` makes a :class:`Run`; every sink (Rerun, reports, evidence files,
the Foxglove export) renders one and computes nothing a stage before it owns.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import astuple, dataclass
from pathlib import Path
from typing import Protocol

from framechain.analysis.egomotion.curves import RotationRateCurves
from framechain.analysis.egomotion.run import CameraMotionEvidence
from framechain.analysis.evidence.alignment import AlignedEvidence
from framechain.analysis.evidence.replayed import Replayed
from framechain.analysis.verdict.findings import AnalysisError, Attribution, Finding, Unattributed
from framechain.config.chain import ChainConfig
from framechain.config.robot import GeneratedRobot
from framechain.replay import ReplayResult, TransformBuffer
from framechain.timeline import LogInfo, Timeline


class ChainSuggestion(Protocol):
    """A chain suggested from the log when none was given (:class:`framechain.suggest.SuggestedChain`, made
    above this room): what a run says of it."""

    @property
    def config(self) -> ChainConfig: ...

    @property
    def placeholders(self) -> Mapping[str, str]:
        """Each frame slot the log cannot fill, and why."""
        ...

    def frames_text(self) -> str:
        """The chain's frames on one line, placeholders marked."""
        ...

    def incomplete_line(self) -> str | None:
        """One line saying what the log lacks of the chain (None: ready to replay)."""
        ...

    def to_yaml(self, *, source: str = "") -> str: ...


@dataclass(frozen=True)
class LoadedRun:
    """The first stage of a run: a log in the model, with the chain to replay it through."""

    path: Path
    timeline: Timeline  # as read
    chain: ChainConfig
    chain_suggested: bool = False  # no chain was given: the one used was suggested from the log
    info: LogInfo | None = None  # what the reader found (format, topics, span, notes); None: a saved timeline
    notes: tuple[str, ...] = ()  # what the reader noticed (a topic the chain names but the log lacks, ...)
    #: what disagrees before any fit (a calibration of another camera's topic): said first, also in ``notes``
    warnings: tuple[str, ...] = ()
    suggestion: ChainSuggestion | None = None  # the suggested chain (placeholders, what the log lacks)
    #: the robot.yaml made for a known arm when a LeRobot dataset came without one; None when it was given
    generated_robot: GeneratedRobot | None = None

    def chain_topic_notes(self) -> list[str]:
        """The reader's notes on the topics the chain names (an undecodable topic, say)."""
        named = [t for t in astuple(self.chain.topics) if isinstance(t, str) and t]
        return [n for n in self.notes if any(n.startswith(f"topic {t}:") for t in named)]


@dataclass(frozen=True)
class NotAttributed:
    """Why a run has no attribution: the typed reason, and one line saying it (without the log's path)."""

    reason: Unattributed
    detail: str


@dataclass(frozen=True)
class Run:
    """A log through its chain: the loaded log, its replay (with the aligned evidence) and the attribution.

    ``replayed.replay`` records each observation's camera row and why nothing replayed;
    ``replayed.aligned`` is the logged evidence aligned to every observation of it. ``attribution`` is
    None when it could not be made, ``not_attributed`` then says why. The stages' values are read by
    their own names too (``run.timeline``, ``run.replay``, ``run.info``, ...).
    """

    loaded: LoadedRun
    replayed: Replayed
    attribution: Attribution | None = None
    not_attributed: NotAttributed | None = None
    #: one line: why no observation was replayed and which chain key to add (None: some were)
    nothing_replayed: str | None = None
    #: each camera's own motion against the frame tree (None: no camera has images, or not attributed)
    camera_motion: CameraMotionEvidence | None = None
    #: each camera of ``camera_motion`` fitted to a link: its rotation rate from its images, as declared and as
    #: fitted (what the report and Rerun draw; :func:`~framechain.analysis.egomotion.curves.rotation_rate_curves`)
    rotation_rates: tuple[RotationRateCurves, ...] = ()

    @property
    def path(self) -> Path:
        return self.loaded.path

    @property
    def timeline(self) -> Timeline:
        """As read (a bearing-only replay's unit depths are in ``replay.observations``)."""
        return self.loaded.timeline

    @property
    def chain(self) -> ChainConfig:
        return self.loaded.chain

    @property
    def chain_suggested(self) -> bool:
        return self.loaded.chain_suggested

    @property
    def info(self) -> LogInfo | None:
        return self.loaded.info

    @property
    def notes(self) -> tuple[str, ...]:
        return self.loaded.notes

    @property
    def warnings(self) -> tuple[str, ...]:
        return self.loaded.warnings

    @property
    def suggestion(self) -> ChainSuggestion | None:
        return self.loaded.suggestion

    @property
    def generated_robot(self) -> GeneratedRobot | None:
        return self.loaded.generated_robot

    @property
    def buffer(self) -> TransformBuffer:
        return self.replayed.buffer

    @property
    def replay(self) -> ReplayResult:
        return self.replayed.replay

    @property
    def aligned(self) -> AlignedEvidence:
        return self.replayed.aligned

    @property
    def findings(self) -> tuple[Finding, ...]:
        return () if self.attribution is None else self.attribution.findings

    def attributed(self) -> Attribution:
        """The attribution; raises :class:`AnalysisError` (one line naming the log) when there is none."""
        if self.attribution is not None:
            return self.attribution
        why = self.not_attributed or NotAttributed(Unattributed.NOT_ASKED, "not attributed")
        raise AnalysisError(f"{self.path}: {why.detail}", why.reason)


__all__ = ["ChainSuggestion", "LoadedRun", "NotAttributed", "Run"]
