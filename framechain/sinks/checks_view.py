"""What a verdict can be checked against, as every output shows it: the bounds of each fault family
(what this log could see and the smallest fault it would have found), the error against each
family's size with the estimate and the bound marked, and the per-label table with the labels to
ignore. The CLI, both reports and Rerun take their rows and words from here.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from framechain.analysis.verdict.checks import Bound, Curve, bound_family, family_name, size_text, tolerance_text
from framechain.analysis.verdict.findings import Attribution
from framechain.arrays import BoolArray, FloatArray
from framechain.sinks.colors import BOUND_COLOR, CORRECTED_COLOR, RECORDED_ERROR_COLOR, hex_color
from framechain.sinks.document import Block, Figures, Heading, Paragraph, Section, table
from framechain.sinks.plots import Figure, new_figure
from framechain.sinks.text import mm

BOUND_COLUMNS = ("fault family", "hop", "smallest fault it would find", "why")
LABEL_COLUMNS = ("label", "observations", "used", "spread (median)", "spread (p90)", "verdict")


def label_columns(result: Attribution) -> tuple[str, ...]:
    """The per-label table's header: a static target's spread, else the error against the evidence."""
    if result.metric == "static_spread":
        return LABEL_COLUMNS
    return ("label", "observations", "used", "error (median)", "error (p90)", "verdict")
#: What the label table measures, per evidence.
LABEL_NOTE = {
    "static_spread": "each label's distance from its own object's position (per window, after the findings)",
    "none": "",
}


def bound_rows(result: Attribution) -> list[tuple[str, str, str, str]]:
    """One row per fault family and hop: its bound (beyond the finding, for a family found), or "not
    observable", and why."""
    found = {(bound_family(f.fault), f.hop, f.camera or "") for f in result.findings}
    return [(b.family + (f" on camera {b.camera}" if b.camera else ""), b.hop.value,
             _bound_cell(b, (b.fault, b.hop, b.camera) in found), b.why) for b in result.bounds]


#: In place of the bounds table when no bound was computed for the run's evidence.
NOT_BOUNDED = ("Not computed for this evidence: the smallest fault this log would have shown is not known, so no "
               "finding does not mean no fault.")


def _bound_cell(bound: Bound, found: bool) -> str:
    """``1.3 ms``; ``13 ms (1 mm tolerance; noise 1.3 ms)`` when the tolerance sets it; ``2 deg (cross-check)``."""
    if bound.size is None:
        return "not observable"
    limit = ""
    if bound.limited_by == "tolerance" and bound.statistical_size is not None:
        limit = (f" ({tolerance_text(bound.tolerance_m)} tolerance; noise "
                 f"{size_text(bound.fault, bound.statistical_size)})")
    elif bound.limited_by == "cross-check":
        limit = " (cross-check)"
    return (f"{size_text(bound.fault, bound.size)}{bound.axes_text()}" + (" beyond the finding" if found else "")
            + limit)


def label_rows(result: Attribution) -> list[tuple[str, str, str, str, str, str]]:
    """The per-label table as text cells."""
    return [(r.label, str(r.observations), str(r.used), mm(r.spread_m), mm(r.p90_m),
             r.verdict + (f" ({r.size_m:g} m, not {r.declared_m:g})" if r.size_m is not None else ""))
            for r in result.labels.rows]


def label_summary(result: Attribution) -> str:
    """One line: how many labels of each verdict, and the ready line to ignore the moving ones."""
    rows = result.labels.rows
    if not rows:
        return ""
    counts: dict[str, int] = {}
    for r in rows:
        counts[r.verdict] = counts.get(r.verdict, 0) + 1
    what = "spread" if result.metric == "static_spread" else "error"
    text = f"labels: {len(rows)} ({', '.join(f'{n} {v}' for v, n in counts.items())}), median {what} " \
           f"{mm(result.labels.overall_m)}"
    line = result.labels.ignore_line()
    text += f"; to leave out the ones that disagree add `{line}`" if line else ""
    sized = result.labels.wrongly_sized
    if sized:
        names = ", ".join(r.label for r in sized)
        text += (f"; {names} {'is' if len(sized) == 1 else 'are'} wrongly sized, not moving (each one's spread grows "
                 f"with its distance from the camera, as a tag of another size gives): declare "
                 f"`{result.labels.size_line()}`")
    return text


def _what_labels_measure(result: Attribution) -> str:
    return LABEL_NOTE.get(result.metric, f"each label's error against the {result.metric.replace('_', ' ')} "
                                         "(after the findings)")


# -- curves -----------------------------------------------------------------------------------
def curve_plots(result: Attribution) -> list[tuple[str, str, Any]]:
    """(name, caption, matplotlib figure) per curve: the error (rms and median) against the family's size,
    the estimate and the bound marked."""
    if not result.curves:
        return []
    out = []
    for curve in result.curves:
        fig, axes = new_figure(6.4, 3.4, columns=2 if curve.key == "offset_s" else 1, top="suptitle")
        _plot_curve(axes[0], curve, zoom=False)
        if curve.key == "offset_s":
            _plot_curve(axes[1], curve, zoom=True)
        name = family_name(curve.fault, curve.hop)
        fig.suptitle(f"Error against the {name} ({curve.hop.value})", fontsize=9)
        caption = (f"{name.capitalize()}: the error against the {result.metric.replace('_', ' ')} as the fault is "
                   "varied, the other findings applied. The fit minimises its root mean square (the dip is the "
                   "estimate); each finding's millimetres are a share of its median")
        out.append((f"curve_{curve.fault.value}_{curve.hop.value}", caption, fig))
    return out


def shown_x(curve: Curve) -> FloatArray:
    """The sizes a curve was measured at, in its plot's unit (:meth:`Curve.display`)."""
    return np.array([curve.display(v) for v in curve.x], dtype=float)


#: A zoomed curve spans this many bounds either side of its estimate (or of no fault), and at least
#: :data:`ZOOM_MIN_HALF` of its plot's unit: the whole range searched is too coarse to see the dip.
ZOOM_BOUNDS = 4.0
ZOOM_MIN_HALF = 20.0


def zoomed(curve: Curve, x: FloatArray) -> BoolArray:
    """Which of the sizes ``x`` (plot units, :func:`shown_x`) a zoomed view of the curve shows."""
    centre = curve.display(curve.estimate if curve.estimate is not None else curve.no_fault)
    out: BoolArray = np.abs(x - centre) <= max(ZOOM_BOUNDS * curve.display(curve.bound or 0.0), ZOOM_MIN_HALF)
    return out


def _plot_curve(ax: Any, curve: Curve, *, zoom: bool) -> None:
    x = shown_x(curve)
    rms, median = np.array(curve.rms_error_m) * 1e3, np.array(curve.median_error_m) * 1e3
    if zoom:
        keep = zoomed(curve, x)
        x, rms, median = x[keep], rms[keep], median[keep]
    ax.plot(x, rms, color=hex_color(RECORDED_ERROR_COLOR), lw=1.2, label="rms (fitted)")
    ax.plot(x, median, color=hex_color(RECORDED_ERROR_COLOR), lw=1.0, ls="-.", label="median (shared out)")
    for i, edge in enumerate(curve.bound_edges() or ()):
        ax.axvline(curve.display(edge), color=hex_color(BOUND_COLOR), ls=":", lw=1.2, label="bound" if i else None)
    ax.axvline(curve.display(curve.no_fault), color=hex_color(BOUND_COLOR), lw=0.8, label="no fault")
    if curve.estimate is not None:
        ax.axvline(curve.display(curve.estimate), color=hex_color(CORRECTED_COLOR), ls="--", lw=1, label="estimate")
    ax.set_xlabel(curve.axis_label() + (" (zoom)" if zoom else ""), fontsize=8)
    ax.set_ylabel("error (mm)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=6)


# -- report section ---------------------------------------------------------------------------
def checks_section(result: Attribution, figures: Sequence[Figure]) -> Section:
    """The report's section on what this log can show (bounds), the curves and the labels (compact in HTML)."""
    blocks: list[Block] = [Paragraph("The smallest fault of each family framechain's own thresholds would have made a "
                                     "finding here, or why the evidence cannot show it.", raw=True)]
    if result.bounds:
        blocks.append(table(BOUND_COLUMNS, bound_rows(result),
                            tone=lambda row: "muted" if row[2] == "not observable" else ""))
    else:
        blocks.append(Paragraph(NOT_BOUNDED))
    if figures:
        blocks.append(Figures(tuple(figures), headed=True))
    if result.labels.rows:
        what = "Spread" if result.metric == "static_spread" else "Error"
        blocks += [Heading("Per label"),
                   Paragraph(f"{what}: {_what_labels_measure(result)}. {label_summary(result)}.", code=True),
                   table(label_columns(result), label_rows(result),
                         tone=lambda row: "" if row[-1] in ("static", "agrees") else "alert")]
    return Section(Heading("What this log can show"), tuple(blocks), compact=True)


__all__ = [
    "BOUND_COLUMNS",
    "LABEL_COLUMNS",
    "NOT_BOUNDED",
    "bound_rows",
    "checks_section",
    "curve_plots",
    "label_columns",
    "label_rows",
    "label_summary",
]
