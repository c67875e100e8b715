"""Sinks: the Rerun stream and the HTML/Markdown reports.

The names below load on first use, so that a process that needs one sink (a renderer process
drawing figures with :mod:`framechain.sinks.plots`) does not import Rerun and the analysis.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from framechain.sinks.report import render_report
    from framechain.sinks.rerun import RerunOptions, RerunOutcome, RerunTarget, stream_replay

_HOMES = {"render_report": "report", "RerunOptions": "rerun", "RerunOutcome": "rerun", "RerunTarget": "rerun",
          "stream_replay": "rerun"}


def __getattr__(name: str) -> Any:
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_HOMES[name]}"), name)


__all__ = ["RerunOptions", "RerunOutcome", "RerunTarget", "render_report", "stream_replay"]
