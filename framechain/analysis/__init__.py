"""The analysis room: fault models, fitting, attribution, the tilt lab."""

from framechain.analysis.attribute import AnalysisError, Attribution, Finding, attribute
from framechain.analysis.corrections import NothingToCorrectError, apply_corrections
from framechain.analysis.lab import TiltRow, crossing_pitch_deg, tilt_sweep

__all__ = [
    "AnalysisError",
    "Attribution",
    "Finding",
    "NothingToCorrectError",
    "TiltRow",
    "apply_corrections",
    "attribute",
    "crossing_pitch_deg",
    "tilt_sweep",
]
