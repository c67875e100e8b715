"""The words every output shares: a finding's cells and sentences, millimetres, the reports' style.

The CLI table, both reports, the Rerun text log and the Foxglove findings word a finding with
:class:`FindingView`, so the same estimate reads the same everywhere; the estimate text itself is
:func:`~framechain.analysis.model.estimates.format_estimate`'s.
"""

from __future__ import annotations

import html
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

from framechain.analysis.model.estimates import format_estimate, format_interval
from framechain.analysis.verdict.findings import Attribution, Finding


def observation_counts(result: Attribution) -> str:
    """``N total, N replayed, rejected ..., N stale``; for a run measured against the cameras' own motion,
    which has no logged observation to replay, the frames and frame pairs each camera's motion was measured on
    (a bare "0 total" there reads as nothing done)."""
    counts = result.counts()
    return measured_instead(result) or (
        f"{counts['total']} total, {counts['replayed']} replayed, rejected {counts['rejected'] or 'none'}, "
        f"{counts['stale']} stale")


def measured_instead(result: Attribution | None) -> str:
    """For a run measured against the cameras' own motion, with no logged observation, what was measured (the
    frames, and the frame pairs measured of those possible with why the rest were left out, per camera); "" for any
    other run."""
    if result is None or result.metric != "camera_motion" or result.counts()["total"]:
        return ""
    measured = "; ".join(f"camera {c['camera']}: {c.get('frames', 0)} frames, {c.get('pairs', 0)} frame pairs"
                         f"{_pairs_left_out(c)}" for c in result.camera_motion)
    return f"none logged (no detections); the cameras' own motion measured instead: {measured}"


#: The reasons a frame pair is left out (``camera_motion`` entries' ``pairs_left_out``), as words.
_LEFT_OUT_WHY = {"too_few_matched_features": "too few matched features", "stamps_out_of_order": "stamps out of order",
                 "too_few_inliers": "too few inliers"}


def _pairs_left_out(entry: Mapping[str, Any]) -> str:
    """`` of P possible (L left out: N why, ...)``: the pairs measured reconcile with those the frames gave."""
    possible = entry.get("pairs_possible")
    if possible is None:
        return ""
    left = {why: int(n) for why, n in (entry.get("pairs_left_out") or {}).items() if n}
    if not left:
        return f" of {possible} possible (none left out)"
    reasons = ", ".join(f"{n} {_LEFT_OUT_WHY.get(why, why)}" for why, n in left.items())
    return f" of {possible} possible ({sum(left.values())} left out: {reasons})"


def mm(value_m: float | None) -> str:
    """A length in metres as millimetres, one decimal (``n/a`` when there is none)."""
    return "n/a" if value_m is None else f"{value_m * 1e3:.1f} mm"


def error_size(value: float | None, unit: str) -> str:
    """An error in its unit: deg/s of a camera's rotation rate (``unit`` "deg/s"), else metres as millimetres."""
    if unit == "deg/s":
        return "n/a" if value is None else f"{value:.2f} deg/s"
    return mm(value)


class FindingCells(NamedTuple):
    """A finding as table cells (each output picks its columns)."""

    fault: str
    hop: str
    estimate: str
    interval: str  # 95% interval
    share: str
    error: str
    confidence: str
    evidence: str
    fix: str
    strength: str = "strong"  # "weak", "note" (under the tolerance: no action needed) or "undetermined"
    camera: str = ""  # the camera the finding concerns ("" for the chain as a whole)


@dataclass(frozen=True)
class FindingView:
    """A finding as every output words it."""

    finding: Finding

    @classmethod
    def of(cls, finding: Finding) -> FindingView:
        return cls(finding)

    def cells(self) -> FindingCells:
        f = self.finding
        return FindingCells(fault=f.fault.value, hop=f.hop.value, estimate=format_estimate(f.estimate),
                            interval=format_interval(f.interval), share=f"{f.share:.0%}", error=self.error(),
                            confidence=f"{f.confidence:.2f}", evidence=f.evidence, fix=f.fix, strength=f.strength,
                            camera=f.camera or "")

    def error(self) -> str:
        """The error the finding explains (its effect): millimetres, or deg/s of a camera's rotation rate."""
        return self.finding.effect_text()

    def fix_label(self) -> str:
        """What its last sentence is: ``fix`` (a change to make), ``note`` (no action needed) or ``undetermined``."""
        return {"note": "note", "undetermined": "undetermined"}.get(self.finding.strength, "fix")

    def text(self) -> str:
        """One line: fault, hop, estimate, share of the error, evidence and fix."""
        line = self.headline()
        f = self.finding
        if f.evidence:
            line += f" Evidence: {f.evidence.rstrip('.')}."
        if f.fix:
            line += f" {self.fix_label().capitalize()}: {f.fix.rstrip('.')}."
        return line

    def headline(self) -> str:
        """Fault, hop, estimate and share of the error, without the evidence and fix sentences."""
        c = self.cells()
        estimate = f"estimate {c.estimate}"
        if self.finding.interval:
            estimate += f" (95% interval {c.interval})"
        size = f"{c.error}, {self.finding.share * 100:.0f}% of the error, confidence {c.confidence}"
        f = self.finding
        lead = {"weak": f"weak ({'; '.join(f.weak_because)}): ", "note": "note (no action needed): ",
                "undetermined": f"undetermined ({'; '.join(f.undetermined_because)}): "}.get(f.strength, "")
        return f"{lead}{c.fault} on {c.hop}{self.on_camera()}; {estimate}; {size}."

    def on_camera(self) -> str:
        """`` on camera <frame>`` for a finding that concerns one camera, else ""."""
        return f" on camera {self.finding.camera}" if self.finding.camera else ""


#: The style of the HTML reports (one log's and the fleet's). A table wider than the page scrolls inside its own
#: box (``display:block``), so the page keeps its width; long words break where :func:`breakable` allows, and code
#: wraps between words, never inside one unless a single word is wider than its cell.
CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;max-width:1100px;color:#222;
line-height:1.45;padding:0 1em}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:1px solid #ddd;padding-bottom:.2em;margin-top:1.6em}
.verdict{font-size:1.2em;background:#fff6e5;border-left:5px solid #f0a020;padding:.7em 1em;margin:1em 0}
.verdict.clean{background:#eaf7ea;border-color:#3a3}
.summary{font-size:1.1em;background:#f3f6fb;border-left:5px solid #4a78c2;padding:.7em 1em}
table{border-collapse:collapse;margin:.6em 0;font-size:.92em;display:block;max-width:100%;overflow-x:auto}
th,td{border:1px solid #ddd;padding:.35em .5em;text-align:left;vertical-align:top;overflow-wrap:break-word}
th{background:#f4f4f4}td.num{text-align:right}
code{background:#f4f4f4;padding:.1em .3em;border-radius:3px;font-size:.9em;word-break:normal;overflow-wrap:break-word}
.plots{display:grid;grid-template-columns:minmax(0,1fr) minmax(0,1fr);gap:1em}.plots figure{margin:0}
figure{margin:1em 0}img{max-width:100%;border:1px solid #eee}.plots img{width:100%}
figcaption{font-size:.85em;color:#555;overflow-wrap:break-word}
.muted{color:#777;font-size:.9em}.nw{white-space:nowrap}
"""

#: A word at least this long gets break opportunities (frame names, paths, JSON keys).
LONG_WORD = 16
_BREAK_AFTER = re.compile(r"(?<=[_/.,:=(\[\]>])")


def breakable(text: str, *, code: bool = False) -> str:
    """``text`` escaped for HTML, with a break opportunity (``<wbr>``) after each ``_ / . , : = ( [ ] >`` inside
    words of :data:`LONG_WORD` characters or more, so that a frame name or a path wraps at its joints and not
    mid-word (and a table of them fits the page). ``code``: a command, whose ``--flag`` and ``a-b`` are kept
    whole (a browser would break after a hyphen)."""
    out = []
    for word in re.split(r"(\s+)", text):
        pieces: list[str] = []
        for piece in (_BREAK_AFTER.split(word) if len(word) >= LONG_WORD else [word]):
            if pieces and len(piece) < 3:  # no break before a last letter or a full stop
                pieces[-1] += piece
            elif piece:
                pieces.append(piece)
        out.append("<wbr>".join(_whole(html.escape(piece)) if code and "-" in piece else html.escape(piece)
                                for piece in pieces))
    return "".join(out)


def _whole(escaped: str) -> str:
    return f"<span class='nw'>{escaped}</span>"


__all__ = ["CSS", "FindingCells", "FindingView", "breakable", "mm", "position_said"]


def position_said(entry: Mapping[str, Any]) -> str:
    """A ``camera_motion`` entry's fitted position, ``[x, y, z] m`` ("" when the position was known)."""
    position = entry.get("position")
    if not isinstance(position, Mapping):
        return ""
    return "[" + ", ".join("nan" if v is None else f"{v:.3f}" for v in position["xyz_link_cam"]) + "] m"
