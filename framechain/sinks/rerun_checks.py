"""What a verdict can be checked against, in a Rerun recording: the bounds and the per-label table as
a document, and the error against each fault family's size as a bar chart (the latency curve also as
a series on its own timeline, ``pose_offset``, the time offset searched)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from framechain.analysis.verdict.checks import Curve, family_name
from framechain.analysis.verdict.findings import Attribution
from framechain.sinks.checks_view import (
    BOUND_COLUMNS,
    NOT_BOUNDED,
    bound_rows,
    label_columns,
    label_rows,
    label_summary,
    shown_x,
    zoomed,
)
from framechain.sinks.colors import BOUND_COLOR, CORRECTED_COLOR, RECORDED_ERROR_COLOR
from framechain.sinks.document import (
    Block,
    Bullets,
    Document,
    Heading,
    ListItem,
    Paragraph,
    Section,
    markdown,
    table,
)

if TYPE_CHECKING:
    import rerun as rr

CHECKS_ENTITY = "/checks"
CURVES_ROOT = "/curves"
#: The timeline of the latency curves' series: the time offset of the pose searched.
OFFSET_TIMELINE = "pose_offset"
#: The legend's colours: the error red, the estimate (the correction found) purple, the bounds grey.
CURVE_COLOR = RECORDED_ERROR_COLOR
ESTIMATE_COLOR = CORRECTED_COLOR


def curve_entity(curve: Curve) -> str:
    return f"{CURVES_ROOT}/{curve.fault.value}_{curve.hop.value}"


def curve_title(curve: Curve) -> str:
    """The chart's tab: short; what the colours are is in the "What this log can show" document."""
    unit = {"offset_s": " (ms)", "angle_deg": " (deg)"}.get(curve.key, "")
    return f"Error vs {family_name(curve.fault, curve.hop)}{unit}"


def log_checks(rec: rr.RecordingStream, result: Attribution, rows: dict[str, int]) -> None:
    """The bounds and labels document, and every curve (static: they have no time)."""
    import rerun as rr

    rec.log(CHECKS_ENTITY, rr.TextDocument(checks_markdown(result), media_type=rr.MediaType.MARKDOWN), static=True)
    rows[CHECKS_ENTITY] = 1
    for curve in result.curves:
        _log_curve(rec, curve, rows)


def _log_curve(rec: rr.RecordingStream, curve: Curve, rows: dict[str, int]) -> None:
    """The rms error (mm, what the fit minimises: its dip is the estimate) as bars over the size searched,
    with the estimate and the bounds as single bars of their own colour, the full height of the curve;
    the latency curve's median also as a series on the ``pose_offset`` timeline."""
    import rerun as rr

    x = shown_x(curve)
    y = np.array(curve.rms_error_m) * 1e3
    finite = np.isfinite(y)
    x, y = x[finite], y[finite]
    if x.size == 0:
        return
    if curve.key == "offset_s":  # the curve near zero and the estimate: the whole second searched is coarse
        keep = zoomed(curve, x)
        x, y = x[keep], y[keep]
    widths = np.gradient(x) * 0.9 if x.size > 1 else np.ones(1)
    entity = curve_entity(curve)
    rec.log(f"{entity}/error", rr.BarChart(y, abscissa=x, widths=widths, color=CURVE_COLOR), static=True)
    rows[f"{entity}/error"] = int(x.size)
    top = float(np.max(y))
    marks = [("estimate", curve.estimate, ESTIMATE_COLOR)] if curve.estimate is not None else []
    edges = curve.bound_edges()
    if edges is not None:
        marks += [("bound_low", edges[0], BOUND_COLOR), ("bound_high", edges[1], BOUND_COLOR)]
    for name, value, color in marks:
        assert value is not None
        mark = rr.BarChart([top], abscissa=[curve.display(value)], widths=[0.3 * float(widths.min())], color=color)
        rec.log(f"{entity}/{name}", mark, static=True)
        rows[f"{entity}/{name}"] = 1
    if curve.key == "offset_s":
        everywhere = np.isfinite(curve.median_error_m)
        offsets = np.asarray(curve.x)[everywhere]
        rec.send_columns(f"{entity}/series", indexes=[rr.TimeColumn(OFFSET_TIMELINE, duration=offsets)],
                         columns=rr.Scalars.columns(scalars=np.asarray(curve.median_error_m)[everywhere] * 1e3))
        rows[f"{entity}/series"] = int(offsets.size)


def checks_markdown(result: Attribution) -> str:
    """The verdict, what this log can show and the per-label table, as Markdown."""
    rows = bound_rows(result)
    blocks: list[Block] = [Paragraph(result.verdict)]
    if rows:
        blocks += [table(BOUND_COLUMNS[:3], (row[:3] for row in rows)),
                   Bullets(tuple(ListItem(f" ({hop}): {why}", lead=family) for family, hop, _, why in rows))]
    else:
        blocks.append(Paragraph(NOT_BOUNDED))
    if result.curves:
        blocks.append(Paragraph("The error against each family's size is in the bar charts (red: the rms error, what "
                                "the fit minimises; purple: the estimate; grey: the bound either side of no fault, or "
                                "of the estimate for a family found)."))
    if result.labels.rows:
        blocks += [Heading("Per label"), Paragraph(label_summary(result)),
                   table(label_columns(result), label_rows(result))]
    return markdown(Document("What this log can show", "", (Section(None, tuple(blocks)),)))


__all__ = ["CHECKS_ENTITY", "CURVES_ROOT", "OFFSET_TIMELINE", "checks_markdown", "curve_entity", "curve_title",
           "log_checks"]
