"""The fleet report: which logs have which fault, the estimates' spread across the fleet, a plot.

Rendered from the fleet table (one row per log and finding; :data:`framechain.fleet.FLEET_SCHEMA`)
as one self-contained HTML page (plots embedded) and Markdown (plots beside it as PNG).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from framechain.analysis.egomotion.recording import CameraRecordingFit
from framechain.analysis.model.estimates import format_interval
from framechain.sinks.colors import FAULT_COLORS, RECORDED_ERROR_COLOR, UNEXPLAINED_COLOR, hex_color
from framechain.sinks.document import (
    Block,
    Bullets,
    Callout,
    Column,
    Document,
    FigureBlock,
    Heading,
    ListItem,
    Paragraph,
    Section,
    table,
    write_document,
)
from framechain.sinks.fleet_cameras import camera_figures, cameras_sections
from framechain.sinks.fleet_offsets import offset_sections, video_offsets
from framechain.sinks.plots import Figure, figure_png, new_figure
from framechain.sinks.text import error_size

#: Rows listed per table before the report points to the Parquet table instead.
MAX_LISTED = 200
STATUS_ORDER = ("findings", "inconclusive", "clean", "no_evidence", "nothing_replayed", "error", "crashed")
STATUS_TEXT = {
    "findings": "with findings",
    "inconclusive": "inconclusive (the fits that would decide are undetermined)",
    "clean": "clean (no fault worth acting on)",
    "no_evidence": "no evidence to measure against",
    "nothing_replayed": "nothing to replay (the reason names the chain key to add)",
    "error": "could not be analysed",
    "crashed": "crashed (computed again on a rerun)",
}
#: The statuses of a log that was not analysed (its error says why).
NOT_ANALYSED = ("nothing_replayed", "error", "crashed")
#: How an estimate is shown: (scale, unit) by estimate_name (offsets in ms, angles in deg, ratios as x).
_DISPLAY = {"offset_s": (1e3, "ms"), "angle_deg": (1.0, "deg"), "factor": (1.0, "x"), "scale": (1.0, "x"),
            "distance_m": (1e3, "mm")}

@dataclass(frozen=True)
class FleetLog:
    """One log (or episode) of the fleet with its findings, gathered from its rows."""

    unit: str
    log: str
    status: str
    error: str | None
    verdict: str | None
    error_median_m: float | None
    findings: list[dict[str, Any]]
    chain: str | None = None  # the chain file (or robot.yaml) it was analysed with (None: the suggested chain)
    metric: str | None = None  # what error_median_m measures (camera_motion: deg/s of rotation rate, else metres)

    @property
    def error_text(self) -> str:
        """The median error in its own unit: deg/s of a camera's rotation rate, or mm."""
        return error_size(self.error_median_m, "deg/s" if self.metric == "camera_motion" else "m")

    @property
    def chain_text(self) -> str:
        return self.chain or "suggested"


@dataclass(frozen=True)
class SpreadRow:
    """The spread of one estimate of one fault across the logs that have it (display units)."""

    fault: str
    hop: str
    estimate_name: str | None
    unit: str
    logs: int
    median: float | None
    p5: float | None
    p95: float | None
    lo: float | None
    hi: float | None
    #: format_estimate's text of the median log's estimate (of the commonest text where there is no number)
    median_text: str = "-"
    #: format_interval's texts of the 5..95th percentiles and of the range ("-" without numbers)
    p5_p95_text: str = "-"
    range_text: str = "-"


def fleet_logs(table: pa.Table) -> list[FleetLog]:
    """The logs of the fleet table in table order, each with its findings (rank order)."""
    logs: dict[str, FleetLog] = {}
    for row in table.to_pylist():
        log = logs.get(row["key"])
        if log is None:
            log = logs[row["key"]] = FleetLog(
                unit=row["unit"], log=row["log"], status=row["status"], error=row["error"], verdict=row["verdict"],
                error_median_m=row["error_median_m"], findings=[], chain=row.get("chain"), metric=row.get("metric"))
        if row["fault"] is not None and row.get("actionable") is not False:  # a note is no fault to act on
            log.findings.append(row)
    return list(logs.values())


@dataclass(frozen=True)
class ReasonRow:
    """One reason logs were not analysed, how many logs gave it, and one of them."""

    status: str
    reason: str
    logs: int
    example: str

    def cells(self) -> list[str]:
        return [self.status, str(self.logs), self.reason, self.example]


REASON_COLUMNS = ("status", "logs", "reason", "for example")


def not_analysed_reasons(logs: Sequence[FleetLog]) -> list[ReasonRow]:
    """The errors of the logs that were not analysed, grouped by message (the log's path taken out), most first."""
    groups: dict[tuple[str, str], list[FleetLog]] = {}
    for log in logs:
        if log.status in NOT_ANALYSED:
            reason = (log.error or "").removeprefix(f"{log.log}: ")
            groups.setdefault((log.status, reason), []).append(log)
    ordered = sorted(groups.items(), key=lambda item: (-len(item[1]), item[0]))
    return [ReasonRow(status=status, reason=reason, logs=len(members), example=members[0].unit)
            for (status, reason), members in ordered]


def estimate_spread(logs: Sequence[FleetLog]) -> list[SpreadRow]:
    """Per (fault, hop, estimate): how many logs have it and the spread of its numeric estimate.

    The numbers are in display units (ms, deg, x) for plots; the texts are the one estimate text
    (``format_estimate``, stored per finding as ``estimate_text``) and ``format_interval``.
    """
    texts: dict[tuple[str, str, str | None], list[str]] = {}
    numeric: dict[tuple[str, str, str | None], list[tuple[float, str]]] = {}  # (SI value, its text)
    for log in logs:
        for f in log.findings:
            key = (f["fault"], f["hop"] + _on_camera(f), f["estimate_name"])
            text = f["estimate_text"] or "-"
            texts.setdefault(key, []).append(text)
            found = numeric.setdefault(key, [])
            if f["estimate_value"] is not None and f["estimate_name"] in _DISPLAY:
                found.append((float(f["estimate_value"]), text))
    rows = []
    for key in sorted(texts, key=lambda k: (-len(texts[k]), k[0], k[1], str(k[2]))):
        pairs = sorted(numeric[key], key=lambda pair: pair[0])
        si = np.asarray([value for value, _text in pairs], dtype=np.float64)
        scale, unit = _DISPLAY.get(key[2] or "", (1.0, ""))
        shown = si * scale
        have = si.size > 0
        if have:
            name = str(key[2])
            median_text = pairs[(si.size - 1) // 2][1]  # the (lower) median log's own estimate text
            p5_p95 = format_interval({name: [float(np.percentile(si, 5)), float(np.percentile(si, 95))]})
            span = format_interval({name: [float(si[0]), float(si[-1])]})
        else:  # estimates without a number (frame swaps, permutations): the commonest text
            median_text = Counter(texts[key]).most_common(1)[0][0]
            p5_p95 = span = "-"
        rows.append(SpreadRow(
            fault=key[0], hop=key[1], estimate_name=key[2], unit=unit, logs=len(texts[key]),
            median=float(np.median(shown)) if have else None,
            p5=float(np.percentile(shown, 5)) if have else None,
            p95=float(np.percentile(shown, 95)) if have else None,
            lo=float(shown.min()) if have else None, hi=float(shown.max()) if have else None,
            median_text=median_text, p5_p95_text=p5_p95, range_text=span,
        ))
    return rows


def render_fleet_report(
    table: pa.Table, out_dir: str | Path, *, formats: Sequence[str] = ("md", "html"), notes: Sequence[str] = (),
    recordings: Mapping[str, Sequence[CameraRecordingFit]] | None = None,
) -> dict[str, Path]:
    """Write fleet_report.md (with its PNGs) and/or fleet_report.html into ``out_dir``; ``notes``: what the batch
    left out and why (files framechain wrote among the inputs); ``recordings``: each dataset's cameras fitted
    across its episodes (:mod:`framechain.fleet.recordings`)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    logs = fleet_logs(table)
    spread = estimate_spread(logs)
    figures = make_fleet_figures(logs)
    cameras = recordings or {}
    offsets = video_offsets(table, cameras)
    camera_figs = camera_figures(cameras)
    doc = fleet_document(logs, spread, figures, notes,
                         [*cameras_sections(cameras, camera_figs), *offset_sections(offsets)])
    return write_document(doc, (*figures, *camera_figs), out, formats, "fleet_report", key_prefix="fleet_")


# -- figures ----------------------------------------------------------------------------------
def make_fleet_figures(logs: Sequence[FleetLog]) -> list[Figure]:
    """Logs per fault and status (bars), and every log's estimate per fault (strip plots)."""
    figures = []
    statuses = [s for s in STATUS_ORDER if any(log.status == s for log in logs)]
    faults: dict[str, int] = {}
    for log in logs:
        for fault in {f["fault"] for f in log.findings}:
            faults[fault] = faults.get(fault, 0) + 1
    fig, (ax_status, ax_fault) = new_figure(9.6, 3.4, columns=2, top="title")
    ax_status.barh(statuses, [sum(log.status == s for log in logs) for s in statuses],
                   color=hex_color(RECORDED_ERROR_COLOR))
    ax_status.set_xlabel("logs")
    ax_status.locator_params(axis="x", integer=True)  # log counts: whole numbers
    ax_status.set_title("Logs by outcome", fontsize=9)
    ax_status.invert_yaxis()
    names = sorted(faults, key=lambda k: (-faults[k], k))  # ties by name: a set's order changes from run to run
    ax_fault.barh(names or ["(none)"], [faults[n] for n in names] or [0],
                  color=[hex_color(FAULT_COLORS.get(n, UNEXPLAINED_COLOR)) for n in names] or None)
    ax_fault.set_xlabel("logs with the fault")
    ax_fault.locator_params(axis="x", integer=True)
    ax_fault.set_title("Faults across the fleet", fontsize=9)
    ax_fault.invert_yaxis()
    figures.append(figure_png(fig, "fleet_faults", "Logs by outcome, and how many logs have each fault"))

    groups: dict[tuple[str, str], list[float]] = {}
    colours: dict[str, tuple[int, int, int]] = {}
    for log in logs:
        for f in log.findings:
            name = f["estimate_name"]
            if f["estimate_value"] is not None and name in _DISPLAY:
                scale, unit = _DISPLAY[name]
                # Per camera, as the table above: two cameras' offsets are two faults, not one spread.
                where = f"on {f['camera']}" if f.get("camera") else f"at {f['hop']}"
                groups.setdefault((f"{f['fault']} {where}", f"{name.split('_')[0]} ({unit})"), []).append(
                    f["estimate_value"] * scale)
                colours[f"{f['fault']} {where}"] = FAULT_COLORS.get(f["fault"], UNEXPLAINED_COLOR)
    if groups:
        rng = np.random.default_rng(0)  # jitter only: the same report for the same table
        n = len(groups)
        fig, axes = new_figure(max(3.2 * n, 4.8), 3.4, columns=n, top="title")
        for ax, ((title, label), values) in zip(axes, sorted(groups.items()), strict=True):
            y = np.asarray(values)
            ax.boxplot(y, widths=0.5, showfliers=False)
            ax.scatter(1 + rng.uniform(-0.15, 0.15, y.size), y, s=10, alpha=0.8, color=hex_color(colours[title]),
                       zorder=3)
            ax.set_xticks([])
            ax.set_ylabel(label)
            ax.set_title(f"{title} ({y.size} log{'s' if y.size != 1 else ''})", fontsize=8)
            ax.grid(True, axis="y", alpha=0.3)
        figures.append(figure_png(fig, "fleet_estimates",
                                  "Each log's estimate, per fault: the spread across the fleet"))
    return figures


# -- text -------------------------------------------------------------------------------------
def summary_line(logs: Sequence[FleetLog]) -> str:
    counts = {s: sum(log.status == s for log in logs) for s in STATUS_ORDER}
    parts = [f"{counts[s]} {STATUS_TEXT[s]}" for s in STATUS_ORDER if counts[s]]
    return f"{len(logs)} log{'s' if len(logs) != 1 else ''}: " + "; ".join(parts) + "."


def chains_line(logs: Sequence[FleetLog]) -> str:
    """``Chains: logs/a/chain.yaml (2 logs); suggested (1 log).``: which chain the logs were analysed with."""
    used = Counter(log.chain_text for log in logs)
    return "Chains: " + "; ".join(f"{name} ({n} log{'s' if n != 1 else ''})"
                                  for name, n in sorted(used.items(), key=lambda item: (-item[1], item[0]))) + "."


def _spread_cells(row: SpreadRow) -> list[str]:
    return [row.fault, row.hop, str(row.logs), row.median_text, row.p5_p95_text, row.range_text]


SPREAD_COLUMNS = ("fault", "hop", "logs", "estimate (median log)", "p5 .. p95", "min .. max")
LOG_COLUMNS = (Column("log", "code"), Column("faults (estimate, share)"), Column("median error", "num"),
               Column("verdict"), Column("chain", "code"))
FAILED_COLUMNS = (Column("log", "code"), Column("status"), Column("error"), Column("chain", "code"))


def _with_findings(logs: Sequence[FleetLog]) -> list[FleetLog]:
    """The logs with findings, largest error first within each unit (metres, then a camera's deg/s: 97 deg/s is not
    larger than 0.1 m)."""
    found = [log for log in logs if log.findings]
    return sorted(found, key=lambda log: (log.metric == "camera_motion", -(log.error_median_m or 0.0)))


def _fault_cell(log: FleetLog) -> str:
    return "; ".join(f"{f['fault']} at {f['hop']}{_on_camera(f)} ({f['estimate_text']}, {f['share']:.0%})"
                     for f in log.findings)


def _on_camera(finding: dict[str, Any]) -> str:
    """`` on camera <frame>`` for a finding on one camera of a rig, else ""."""
    camera = finding.get("camera")
    return f" on camera {camera}" if camera else ""


def fleet_document(logs: Sequence[FleetLog], spread: Sequence[SpreadRow], figures: Sequence[Figure],
                   notes: Sequence[str] = (), recordings: Sequence[Section] = ()) -> Document:
    """The fleet report: the outcome, the faults across the fleet, the ``recordings`` sections (each recording's
    cameras and offsets), which logs have which fault, and why logs were not analysed."""
    overview = Section(None, (Callout(summary_line(logs), kind="summary"), Paragraph(chains_line(logs)),
                              Bullets(tuple(ListItem(f"note: {n}") for n in notes), muted=True)))
    faults = Section(Heading("Faults across the fleet"), (
        table(SPREAD_COLUMNS, (_spread_cells(r) for r in spread)) if spread else Paragraph("No log has a finding."),
        *(FigureBlock(fig) for fig in figures)))
    found = _with_findings(logs)
    listed: tuple[Block, ...] = (Paragraph("None."),)
    if found:
        rows = ([log.unit, _fault_cell(log), log.error_text, log.verdict or "", log.chain_text]
                for log in found[:MAX_LISTED])
        listed = (table(LOG_COLUMNS, rows), *_more(len(found)))
    which = Section(Heading("Which logs have which fault"), listed)
    query = "Every row of fleet.parquet is one log and finding; query it with DuckDB or pandas."
    footer = Section(None, (Paragraph(query, only="md"),
                            Paragraph(f"Written by framechain batch. {query}", muted=True, only="html")))
    return Document("framechain fleet report", "framechain fleet report",
                    (overview, faults, *recordings, which, *_not_analysed_sections(logs), footer), pipe="\\|")


def _not_analysed_sections(logs: Sequence[FleetLog]) -> list[Section]:
    failed = [log for log in logs if log.status in NOT_ANALYSED]
    if not failed:
        return []
    reasons = table(REASON_COLUMNS, (r.cells() for r in not_analysed_reasons(logs)), joined=True)
    listed = table(FAILED_COLUMNS, ([log.unit, log.status, log.error or "", log.chain_text]
                                    for log in failed[:MAX_LISTED]), joined=True)
    return [Section(Heading("Why logs were not analysed"), (reasons,)),
            Section(Heading("Logs that could not be analysed"), (listed, *_more(len(failed))))]


def _more(n: int) -> list[Paragraph]:
    """The line under a table cut at :data:`MAX_LISTED` rows."""
    if n <= MAX_LISTED:
        return []
    return [Paragraph(f"... and {n - MAX_LISTED} more in fleet.parquet.", muted=True, joined=True)]


__all__ = [
    "FleetLog",
    "ReasonRow",
    "SpreadRow",
    "chains_line",
    "estimate_spread",
    "fleet_document",
    "fleet_logs",
    "not_analysed_reasons",
    "render_fleet_report",
]
