"""One run: a log read, replayed, aligned and attributed, each stage computed once and handed down.

:func:`framechain.pipeline.run` makes a :class:`Run`; every sink (Rerun, reports, evidence files,
the Foxglove export) renders one and computes nothing a stage before it owns.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from framechain.analysis.egomotion.curves import RotationRateCurves
from framechain.analysis.egomotion.run import CameraMotionEvidence
from framechain.analysis.evidence.alignment import AlignedEvidence
from framechain.analysis.verdict.findings import AnalysisError, Attribution, Finding, Unattributed
from framechain.config.chain import ChainConfig
from framechain.replay import ReplayResult, TransformBuffer
from framechain.timeline import Timeline


@dataclass(frozen=True)
class NotAttributed:
    """Why a run has no attribution: the typed reason, and one line saying it (without the log's path)."""

    reason: Unattributed
    detail: str


@dataclass(frozen=True)
class Run:
    """A log through its chain: what was read, the replay, the aligned evidence and the attribution.

    ``replay`` records each observation's camera row and why nothing replayed; ``aligned`` is the
    logged evidence aligned to every observation of ``replay``. ``attribution`` is None when it could
    not be made, ``not_attributed`` then says why.
    """

    path: Path
    timeline: Timeline  # as read (a bearing-only replay's unit depths are in ``replay.observations``)
    chain: ChainConfig
    buffer: TransformBuffer
    replay: ReplayResult
    aligned: AlignedEvidence
    attribution: Attribution | None = None
    not_attributed: NotAttributed | None = None
    #: one line: why no observation was replayed and which chain key to add (None: some were)
    nothing_replayed: str | None = None
    chain_suggested: bool = False  # no chain was given: the one used was suggested from the log
    suggestion: Any = None  # the suggestion (placeholders, what the log lacks) when no chain was given
    info: Any = None  # the adapter's LogInfo (format, topics, span, notes) when read from a robot log
    notes: tuple[str, ...] = ()  # what the reader noticed (a topic the chain names but the log lacks, ...)
    #: what disagrees before any fit (a calibration of another camera's topic): said first, also in ``notes``
    warnings: tuple[str, ...] = ()
    #: each camera's own motion against the frame tree (None: no camera has images, or not attributed)
    camera_motion: CameraMotionEvidence | None = None
    #: each camera of ``camera_motion`` fitted to a link: its rotation rate from its images, as declared and as
    #: fitted (what the report and Rerun draw; :func:`~framechain.analysis.egomotion.curves.rotation_rate_curves`)
    rotation_rates: tuple[RotationRateCurves, ...] = ()
    #: the robot.yaml made for a known arm when a dataset came without one (text, the line saying what it
    #: assumed, the episode); None when robot.yaml was given
    generated_robot: Any = None

    @property
    def findings(self) -> tuple[Finding, ...]:
        return () if self.attribution is None else self.attribution.findings

    def attributed(self) -> Attribution:
        """The attribution; raises :class:`AnalysisError` (one line naming the log) when there is none."""
        if self.attribution is not None:
            return self.attribution
        why = self.not_attributed or NotAttributed(Unattributed.NOT_ASKED, "not attributed")
        raise AnalysisError(f"{self.path}: {why.detail}", why.reason)


__all__ = ["NotAttributed", "Run"]
