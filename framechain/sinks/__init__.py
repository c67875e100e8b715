"""Sinks: the Rerun stream and the HTML/Markdown reports."""

from framechain.sinks.report import render_report
from framechain.sinks.rerun import RerunOptions, RerunOutcome, RerunTarget, stream_replay

__all__ = ["RerunOptions", "RerunOutcome", "RerunTarget", "render_report", "stream_replay"]
