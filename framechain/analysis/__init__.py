"""The analysis room: one replay and its aligned evidence, fault models, fitting, attribution (with the
bounds of what the evidence could see), the run every sink renders, the tilt lab."""

from framechain.analysis.evidence.replayed import Replayed, replay_chain
from framechain.analysis.lab import TiltRow, crossing_pitch_deg, tilt_sweep
from framechain.analysis.run import LoadedRun, NotAttributed, Run
from framechain.analysis.verdict.attribute import AnalysisError, Attribution, Finding, attribute_replayed
from framechain.analysis.verdict.checks import Bound, Curve, LabelTable
from framechain.analysis.verdict.corrections import NothingToCorrectError, apply_corrections
from framechain.analysis.verdict.findings import Unattributed

__all__ = [
    "AnalysisError",
    "Attribution",
    "Bound",
    "Curve",
    "Finding",
    "LabelTable",
    "LoadedRun",
    "NotAttributed",
    "NothingToCorrectError",
    "Replayed",
    "Run",
    "TiltRow",
    "Unattributed",
    "apply_corrections",
    "attribute_replayed",
    "crossing_pitch_deg",
    "replay_chain",
    "tilt_sweep",
]
