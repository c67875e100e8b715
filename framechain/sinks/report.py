"""Reports: one self-contained HTML page (plots embedded, no network) and Markdown beside its plots.

Order: the verdict in one sentence, the findings (estimates, intervals, fixes), the observation
accounting, then the pictures people would rather look at than read (error per hop over time,
error against robot speed, world points from above, the sensitivity of the fault found), then
provenance (file, topics, frames, units, stamps, configuration).
"""

from __future__ import annotations

import html
import json
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from framechain.analysis.run import Run
from framechain.analysis.verdict.checks import nothing_observable, tolerance_text
from framechain.analysis.verdict.findings import Attribution, Finding
from framechain.analysis.verdict.sensitivity import robot_speed, sensitivity
from framechain.arrays import FloatArray, IntArray
from framechain.catalogue import HopName
from framechain.sinks.checks_view import checks_html, checks_markdown, curve_plots
from framechain.sinks.colors import (
    AS_RUN_COLOR,
    BOUND_COLOR,
    CORRECTED_COLOR,
    ERROR_LINE_LEGEND,
    FAULT_COLORS,
    HOP_COLORS,
    HOP_LEGEND,
    LEGEND,
    RECOMPUTED_COLOR,
    RECORDED_ERROR_COLOR,
    REFERENCE_COLOR,
    UNEXPLAINED_COLOR,
    hex_color,
    legend_text,
)
from framechain.sinks.evidence_files import inputs_record, write_attribution
from framechain.sinks.overlay import ImageOverlay
from framechain.sinks.plots import Figure, figure_html, figure_png, new_figure
from framechain.sinks.text import CSS, FindingView, breakable, mm
from framechain.timeline import PointRole


def write_outputs(run: Run, out_dir: str | Path, *, formats: Sequence[str] = ("md", "html"),
                  say: Callable[[str], None] = lambda _m: None) -> dict[str, Path]:
    """The attribution's files (:func:`write_attribution`), then the report in ``formats`` (:func:`render_report`).

    The report's plots are made first: where renderers run (:func:`framechain.sinks.plots.renderers`), they
    draw them while this process writes the other files and crops the camera images.
    """
    plots = _plots(run)
    paths = write_attribution(run, out_dir)
    say(f"writing the report ({', '.join(formats)})")
    paths.update(_write_report(run, Path(out_dir), formats, plots))
    return paths


def render_report(run: Run, out_dir: str | Path, *, formats: Sequence[str] = ("md", "html")) -> dict[str, Path]:
    """Write report.md (with its PNGs) and/or report.html of the run's attribution into ``out_dir``.

    Both show what the camera saw at the worst observations, with the chain drawn on the image
    (:func:`image_crops`), where the log has camera images.
    """
    return _write_report(run, Path(out_dir), formats, _plots(run))


def _plots(run: Run) -> tuple[list[Figure], list[Figure]]:
    """The report's pictures and the plots of its checks (made now: drawn here, or sent to the renderers)."""
    result = run.attributed()
    # Measured against the cameras' own motion, the world-error pictures would be empty.
    pictures = motion_figures(run) + (make_figures(result) if result.metric != "camera_motion" else [])
    if result.metric == "none":  # no evidence: the error plots would be empty axes
        pictures = [f for f in pictures if f.name not in ("error_per_hop", "error_vs_speed")]
    return pictures, [figure_png(fig, name, caption) for name, caption, fig in curve_plots(result)]


def _write_report(run: Run, out: Path, formats: Sequence[str], plots: tuple[list[Figure], list[Figure]]
                  ) -> dict[str, Path]:
    result = run.attributed()
    out.mkdir(parents=True, exist_ok=True)
    pictures, checks = plots
    sections = image_crops(run)
    paths: dict[str, Path] = {}
    if "md" in formats:
        for fig in [*pictures, *checks]:
            (out / f"{fig.name}.png").write_bytes(fig.png)
        paths["md"] = out / "report.md"
        for _, crops in sections:
            for crop in crops:
                (out / f"{crop.name}.png").write_bytes(crop.png)
        text = markdown(result, pictures).replace("## Provenance", checks_markdown(result, checks) + "## Provenance", 1)
        paths["md"].write_text(text + _crops_markdown(result, sections))
    if "html" in formats:
        paths["html"] = out / "report.html"
        page = html_page(result, pictures)
        provenance = "<h2>Provenance</h2>"
        inserted = checks_html(result, checks, figure_html) + _crops_html(result, sections) + provenance
        paths["html"].write_text(page.replace(provenance, inserted, 1))
    return paths


# -- what the camera saw ----------------------------------------------------------------------
#: Legend of the image crops (the colours of framechain.sinks.colors).
CROP_LEGEND = ("green: the detection (and tag corners; a small light-green dot inside: the tag centre framechain "
               "estimated from them); blue: the recomputed world point projected back into the image; orange: the "
               "as-run world point projected the same way; the line between them")
#: Metrics whose findings are the robot's own mistakes: the as-run points carry them, one per finding.
AS_RUN_METRICS = ("logged_hops", "target")
#: A finding whose own gap is under this share of the image width is shown zoomed in.
ZOOM_BELOW = 0.05
#: Half-size (image pixels) of a zoomed crop around the points, at least.
ZOOM_HALF_PX = 12.0


def image_crops(run: Run) -> list[tuple[str, list[Figure]]]:
    """Per finding (or once, without findings): the camera image at the worst observations for it,
    with the detection, both projected world points and the line between them, in the colour of that
    finding. With several findings of the robot's own (as-run evidence), each shows its own effect
    alone: the as-run point less what the other findings do (:func:`finding_overlay`); a gap too small
    to see in the whole image is shown zoomed in around the points.

    A finding's worst observations are those where its hop departs most from the logged hop
    (``hop_errors``), else where the error against the evidence is largest."""
    from framechain.sinks.overlay import image_overlay, render_crops, worst_rows

    result, timeline = run.attributed(), run.timeline
    overlay = image_overlay(timeline, run.replay, run.aligned, run.findings)
    obs = run.replay.observations
    n = len(obs)

    def score_for(hop: str | None) -> FloatArray:
        for candidate in (result.hop_errors.get(hop) if hop else None, result.error_before):
            if candidate is not None and len(candidate) == n and np.isfinite(candidate).any():
                return np.asarray(candidate, dtype=float)
        return overlay.error_px

    sections: list[tuple[str, list[Figure]]] = []
    for k, finding in enumerate(result.findings or (None,)):
        shown, alone = (overlay, False) if finding is None else finding_overlay(run, overlay, k)
        rows = worst_rows(timeline, run.replay, shown, score_for(finding.hop.value if finding else None))
        gaps = shown.error_px[rows]
        small = bool(rows.size) and np.isfinite(gaps).any() and float(np.nanmax(gaps)) < ZOOM_BELOW * float(
            np.max(shown.width[rows]))
        prefix = f"camera_{finding.fault.value}" if finding else "camera"
        what_gap = "between recomputed and as-run less the other findings" if alone else "between as-run and recomputed"
        figures = []
        for i, png in render_crops(timeline, shown, rows, zoom_px=ZOOM_HALF_PX if small else None):
            gap = shown.error_px[i]
            what = f"{gap:.1f} px {what_gap}" if np.isfinite(gap) else "no as-run point"
            zoomed = " (zoomed in around the points)" if small else ""
            caption = f"obs {int(obs.obs_id[i])} {obs.label[i]} at {obs.stamp_ns[i] / 1e9:.3f} s: {what}{zoomed}"
            figures.append(Figure(f"{prefix}_obs_{int(obs.obs_id[i])}", caption, png))
        if figures:
            title = "the worst observations" if finding is None else (
                f"{finding.fault.value} on {finding.hop.value}{' alone' if alone else ''}: where {finding.hop.value} "
                "departs most")
            sections.append((title, figures))
    return sections


def finding_overlay(run: Run, overlay: ImageOverlay, index: int) -> tuple[ImageOverlay, bool]:
    """The overlay of finding ``index`` of the run's attribution: in its colour, and where several findings are the
    robot's own and the as-run points carry them all, with the as-run points less the other findings' effect
    (``Attribution.others_shift``), so that the picture shows this finding alone. The bool: whether it does."""
    from framechain.sinks.overlay import project_world_points

    result, replay = run.attributed(), run.replay
    finding = result.findings[index]
    own = replace(overlay, finding=finding, color=FAULT_COLORS.get(finding.fault.value, UNEXPLAINED_COLOR))
    role = {"world": PointRole.HOP_WORLD, "target": PointRole.TARGET}.get(overlay.as_run_role)
    replayed = np.flatnonzero(replay.replayed)
    if (len(result.findings) < 2 or result.metric not in AS_RUN_METRICS or role is None
            or index >= len(result.others_shift) or len(result.others_shift[index]) != replayed.size):
        return own, False
    shift = np.full((len(replay.observations), 3), np.nan)
    shift[replayed] = result.others_shift[index]
    as_run = run.aligned.points(role) - shift
    return replace(own, as_run_uv=project_world_points(run.timeline, replay, as_run)), True


def _crops_intro(result: Attribution) -> str:
    alone = len(result.findings) > 1 and result.metric in AS_RUN_METRICS
    if alone:
        return (f"Per finding, its own effect alone, at the observations where its hop departs most: {CROP_LEGEND}, "
                "in the colour of the finding, with the as-run point less what the other findings do to it "
                "(a gap of a few pixels is shown zoomed in).")
    top = max(result.findings, key=lambda f: f.share) if result.findings else None
    colour = f", in the colour of {top.fault.value} on {top.hop.value} (the largest share)" if top else ""
    return f"Per finding, at the observations where its hop departs most: {CROP_LEGEND}{colour}."


def _crops_markdown(result: Attribution, sections: Sequence[tuple[str, list[Figure]]]) -> str:
    if not sections:
        return ""
    lines = ["", "## What the camera saw", "", _crops_intro(result), ""]
    for title, crops in sections:
        lines += [f"### {title}", "", *[f"![{c.caption}]({c.name}.png)" for c in crops], ""]
    return "\n".join(lines)


def _crops_html(result: Attribution, sections: Sequence[tuple[str, list[Figure]]]) -> str:
    if not sections:
        return ""
    e = html.escape
    parts = [f"<h2>What the camera saw</h2><p>{e(_crops_intro(result))}</p>"]
    for title, crops in sections:
        parts.append(f"<h3>{e(title)}</h3><div class='plots'>")
        parts += [figure_html(c) for c in crops]
        parts.append("</div>")
    return "".join(parts)


# -- figures ----------------------------------------------------------------------------------
def make_figures(result: Attribution) -> list[Figure]:
    """The report's pictures of the error: each drawn only where it shows what its caption says."""
    figures = [_error_over_time(result)]
    speed = robot_speed(result)
    if np.isfinite(speed).any() and float(np.nanmax(speed)) > STILL_SPEED_M_S:  # a body that never moves: no signature
        figures.append(_error_against_speed(result, speed))
    figures.append(_world_top_down(result))
    top = next((f for f in result.findings if f.actionable), None)
    if top is not None:
        sensitivity_figure = _sensitivity(result, top)
        if sensitivity_figure is not None:
            figures.append(sensitivity_figure)
    return figures


#: A body whose speed stays under this (m/s) at every observation does not move: error against speed is not drawn.
STILL_SPEED_M_S = 1e-3


def _error_over_time(result: Attribution) -> Figure:
    """The error against the evidence over time, as recorded and after the findings; each logged hop's own error
    where the robot logged its hops (then it is "error per hop")."""
    inputs = result.inputs
    t = (inputs.stamp_ns - inputs.stamp_ns.min()) * 1e-9 if len(inputs) else np.zeros(0)
    metric = result.metric.replace("_", " ")
    fig, (ax,) = new_figure(6.4, 3.6)
    # The error as recorded goes underneath, wide and pale, so a hop that carries all of it stays visible.
    _line(ax, t, result.error_before * 1e3, lw=4, color=hex_color(RECORDED_ERROR_COLOR), alpha=0.35,
          label=f"error against the {metric}, as recorded")
    for (hop, errors), style in zip(result.hop_errors.items(), ("-", "--", ":"), strict=False):
        _line(ax, t, errors * 1e3, lw=1.2, ls=style, color=hex_color(HOP_COLORS[HopName(hop)]),
              label=f"{hop} (logged vs recomputed)")
    if result.findings:
        _line(ax, t, result.error_after * 1e3, lw=1, color=hex_color(CORRECTED_COLOR), ls="--",
              label=_after_label(result))
    ax.set_xlabel("time since first observation (s)")
    ax.set_ylabel("error (mm)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    if result.hop_errors:
        return figure_png(fig, "error_per_hop", "Error per hop over time: each logged hop's own departure, and the "
                          f"error against the {metric}")
    return figure_png(fig, "error_per_hop", f"Error against the {metric} over time (no hop logged: one error, as "
                      "recorded and after the findings)")


def _error_against_speed(result: Attribution, speed: FloatArray) -> Figure:
    fig, (ax,) = new_figure(6.4, 3.6, top="title")
    _dots(ax, speed, result.error_before * 1e3, alpha=0.6, color=hex_color(RECORDED_ERROR_COLOR), label="as recorded")
    if result.findings:
        _dots(ax, speed, result.error_after * 1e3, alpha=0.6, color=hex_color(CORRECTED_COLOR),
              label=_after_label(result))
    ax.set_xlabel("robot speed (m/s)")
    ax.set_ylabel("error (mm)")
    ax.set_title("A latency grows with speed", fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    return figure_png(fig, "error_vs_speed", "Error against robot speed (the latency signature)")


def _sensitivity(result: Attribution, top: Finding) -> Figure | None:
    """How far the top finding's fault moves the world points as it grows, against the chain's tolerance."""
    x, err, label = sensitivity(result, top)
    if not x.size:
        return None
    tolerance = result.config.tolerance_m
    fig, (ax,) = new_figure(6.4, 3.6, top="title")
    ax.plot(x, err * 1e3, color=hex_color(FAULT_COLORS.get(top.fault.value, UNEXPLAINED_COLOR)),
            label=top.fault.value)
    ax.axhline(tolerance * 1e3, color=hex_color(BOUND_COLOR), ls="--", lw=1,
               label=f"the {tolerance_text(tolerance)} tolerance (tolerance_m)")
    ax.axvline(x[-1] / 1.5, color=hex_color(CORRECTED_COLOR), ls="--", lw=1, label="the estimate")
    ax.set_xlabel(label)
    # How far the world points move, not the error against the evidence the findings share out
    # (that is the curves' measure): a depth scale moves points far and static spreads little.
    ax.set_ylabel("median displacement of the world points (mm)")
    ax.set_title(f"Sensitivity: how far {top.fault.value} at {top.hop.value} moves the world points", fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    return figure_png(fig, "sensitivity", f"How far {top.fault.value} moves the world points on this episode, up to "
                      "1.5 times its estimate (a displacement, not the error the findings share out)")


def _world_top_down(result: Attribution) -> Figure:
    """The world points from above: recomputed, the evidence and (against a reference or static targets) corrected."""
    recomputed = result.replay.p_world[result.replay.replayed]  # the replay's own, row for row the inputs'
    fig, (ax,) = new_figure(6.4, 4.4)
    _dots(ax, recomputed[:, 0], recomputed[:, 1], label="recomputed from the log", alpha=0.7,
          color=hex_color(RECOMPUTED_COLOR))
    ev = result.evidence_points
    if np.isfinite(ev).any() and result.metric != "static_spread":
        label = {"logged_hops": "as-run (robot's logged)", "target": "as-run target", "reference": "reference"}.get(
            result.metric, "evidence"
        )
        color = REFERENCE_COLOR if result.metric == "reference" else AS_RUN_COLOR
        _dots(ax, ev[:, 0], ev[:, 1], marker="x", label=label, alpha=0.7, color=hex_color(color))
    if result.findings and result.metric in ("reference", "static_spread"):
        _dots(ax, result.corrected_world[:, 0], result.corrected_world[:, 1], label="corrected", alpha=0.7,
              color=hex_color(CORRECTED_COLOR))
    ax.set_xlabel(f"x in {result.config.frames.world} (m)")
    ax.set_ylabel(f"y in {result.config.frames.world} (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    return figure_png(fig, "world_top_down", "World points from above")


#: Marker of the scatter plots: scatter(s=8)'s size (the square root of its area in points^2) and edge.
_DOT_PT = 8.0**0.5
_DOT_EDGE_PT = 1.0
#: A line of more points than this many per column of the plot is thinned to what draws the same.
_LINE_COLUMNS = 1000


def _dots(ax: Any, x: FloatArray, y: FloatArray, **style: Any) -> None:
    """A scatter of one colour as a line of markers: drawn the same as ``ax.scatter(x, y, s=8)``, but
    one path instead of a collection, which the legend places ("best") without a Python loop per point."""
    ax.plot(x, y, ls="none", marker=style.pop("marker", "o"), ms=_DOT_PT, mew=_DOT_EDGE_PT, **style)


def _line(ax: Any, t: FloatArray, y: FloatArray, **style: Any) -> None:
    """``ax.plot(t, y)`` thinned to the points that draw it: per run of points narrower than a column
    of the plot, its first, last, lowest and highest (and where a gap starts), in order."""
    keep = _drawn_points(y, _LINE_COLUMNS)
    ax.plot(t[keep], y[keep], **style)


def _drawn_points(y: FloatArray, columns: int) -> IntArray:
    """Indices of a series that draw the same line as all of it at ``columns`` runs (see :func:`_line`)."""
    n = y.shape[0]
    if n <= 4 * columns:
        return np.arange(n)
    run = np.arange(n) * columns // n  # runs of consecutive points
    starts = np.flatnonzero(np.r_[True, run[1:] != run[:-1]])
    finite = np.isfinite(y)
    low = np.where(finite, y, np.inf)
    high = np.where(finite, y, -np.inf)
    lowest = np.lexsort((low, run))[starts]  # sorted by run, then value: a run's first is its lowest
    highest = np.lexsort((-high, run))[starts]
    gaps = np.flatnonzero(~finite & np.r_[True, finite[:-1]])
    out: IntArray = np.unique(np.concatenate([starts, np.r_[starts[1:], n] - 1, lowest, highest, gaps]))
    return out


def motion_figures(run: Run) -> list[Figure]:
    """Per measured camera: |rotation rate| over time from its images, from forward kinematics as declared and
    as fitted (a time offset shows as a shift, the picture of :mod:`framechain.sinks.rerun_egomotion`)."""
    out = []
    for curves in run.rotation_rates:
        t = curves.middle_ns * 1e-9
        fig, (ax,) = new_figure(6.4, 3.6, top="title")
        ax.plot(t, curves.measured.magnitude_deg_s, color="k", lw=1.6, label="from the images")
        ax.plot(t, curves.declared.magnitude_deg_s, color=hex_color(AS_RUN_COLOR), lw=1.0,
                label=f"forward kinematics of {curves.declared_link} as declared")
        ax.plot(t, curves.fitted.magnitude_deg_s, color=hex_color(CORRECTED_COLOR), lw=1.0, ls="--",
                label=f"{curves.link} shifted {curves.offset_s * 1e3:+.1f} ms, fitted mount")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("rotation rate (deg/s)")
        ax.set_title(f"Camera {curves.camera}: its own motion against forward kinematics", fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
        name = "rotation_rate_" + "".join(c if c.isalnum() else "_" for c in curves.camera)
        out.append(figure_png(fig, name, f"Rotation rate of {curves.camera}: images against forward kinematics"))
    return out


def _size(value: float | None, summary: dict[str, Any]) -> str:
    """An error summary's value in its unit: millimetres, or deg/s of a camera's rotation rate."""
    if summary.get("unit") == "deg/s":
        return "n/a" if value is None else f"{value:.2f} deg/s"
    return mm(value)


def _error_sentence(result: Attribution) -> str:
    """The error against the evidence and what the findings leave (or that there is no evidence to measure it)."""
    s = result.error_summary()
    if result.metric == "none":
        return "No error measured: the log has no evidence to measure the chain against."
    return (f"Against the {s['metric'].replace('_', ' ')}: median {_size(s['median'], s)}, p95 {_size(s['p95'], s)}, "
            f"max {_size(s['max'], s)}; {_after_label(result)}: "
            f"median {_size(result.error_summary(result.error_after)['median'], s)}.")


def _after_label(result: Attribution) -> str:
    """What the second error curve is: corrected data, or what the findings leave unexplained."""
    if result.metric in ("reference", "static_spread"):
        return "after correcting the recorded data"
    return "left unexplained by the findings"


# -- text -------------------------------------------------------------------------------------
HOP_COLUMNS = ("hop", "own departure med / p95 / max", "sample gap med / max", "stale", "attributed to it")


def hop_rows(result: Attribution) -> list[tuple[str, ...]]:
    """The per-hop summary as text cells (the CLI, Markdown and HTML share it)."""
    rows: list[tuple[str, ...]] = []
    for r in result.hop_summary():
        dep = r["departure_m"]
        gap = r["gap_ms"]
        faults = f" ({', '.join(r['faults'])})" if r["faults"] else ""
        rate = sum(f.error_m for f in result.findings if f.hop.value == r["hop"] and f.error_unit == "deg/s")
        rows.append((
            r["hop"],
            "not logged" if dep is None else f"{mm(dep['median'])} / {mm(dep['p95'])} / {mm(dep['max'])}",
            "-" if gap is None else f"{gap['median']:.1f} / {gap['max']:.1f} ms",
            str(r["stale"]),
            f"{rate:.2f} deg/s{faults}" if rate else f"{mm(r['attributed_m'])}{faults}",
        ))
    return rows


def _provenance(result: Attribution) -> list[tuple[str, str]]:
    record = inputs_record(result)
    src = record["source"]
    counts = record["observations"]
    return [
        ("file", str(src.get("path", ""))),
        ("format", str(src.get("format", ""))),
        (
            "frames",
            f"camera {record['frames']['camera']}, body {record['frames']['body']}, world {record['frames']['world']}",
        ),
        ("topics", json.dumps(record["topics"])),
        (
            "camera",
            f"{record['camera']['width']}x{record['camera']['height']}, K {record['camera']['K']}, "
            f"distortion {record['camera']['distortion_model']}",
        ),
        ("units", "; ".join(f"{k}: {v}" for k, v in record["units"].items())),
        (
            "stamps",
            f"observations from {record['stamps']['observations_first_ns']} to "
            f"{record['stamps']['observations_last_ns']} ns, {record['stamps']['keyed_on']}",
        ),
        ("metric", f"{record['metric']['name']}: {record['metric']['definition']}"),
        ("logged points", "; ".join(
            f"{role}: " + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in fates.items())
            for role, fates in record["evidence_alignment"].items()) or "none"),
        ("latency budget", f"{record['latency_budget_s'] * 1e3:g} ms"),
        (
            "observations",
            f"{counts['total']} total, {counts['replayed']} replayed, rejected "
            f"{counts['rejected'] or 'none'}, {counts['stale']} stale",
        ),
        ("configuration", json.dumps(record["configuration"])),
        ("seed", str(record["seed"])),
        ("framechain", str(record["framechain_version"])),
    ]


def markdown(result: Attribution, figures: Sequence[Figure]) -> str:
    lines = [
        f"# framechain report: {Path(str(result.source.get('path', ''))).name or 'episode'}",
        "",
        f"**{result.verdict}**",
        "",
        "## Findings",
        "",
    ]
    if result.findings:
        lines += [
            "| fault | hop | camera | estimate | 95% interval | share | effect | confidence | strength | fix |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        for c in (FindingView.of(f).cells() for f in result.findings):
            lines.append(f"| {c.fault} | {c.hop} | {c.camera or '-'} | {c.estimate} | {c.interval} | {c.share} | "
                         f"{c.error} | {c.confidence} | {c.strength} | {c.fix.replace('|', '/')} |")
        lines += [""] + [f"- **{f.fault.value}**{FindingView.of(f).on_camera()}: {f.evidence}"
                         for f in result.findings]
    else:
        lines.append(_no_findings(result))
    lines += [
        "",
        "## Error",
        "",
        _error_sentence(result),
        "",
        "### Per hop",
        "",
        "| " + " | ".join(HOP_COLUMNS) + " |",
        "| " + " | ".join("---" for _ in HOP_COLUMNS) + " |",
        *("| " + " | ".join(row) + " |" for row in hop_rows(result)),
        "",
        f"Colours, in every plot and picture here, in Rerun and in the Foxglove export: {legend_text()}",
        "",
    ]
    if result.notes:
        lines += ["## Notes", "", *(f"- {n.replace('|', '/')}" for n in result.notes), ""]
    for fig in figures:
        lines += [f"### {fig.caption}", "", f"![{fig.caption}]({fig.name}.png)", ""]
    lines += ["## Provenance", "", "| | |", "| --- | --- |"]
    lines += [f"| {k} | {v.replace('|', '/')} |" for k, v in _provenance(result)]
    return "\n".join(lines) + "\n"


def html_page(result: Attribution, figures: Sequence[Figure]) -> str:
    e = html.escape
    title = Path(str(result.source.get("path", ""))).name or "episode"
    parts = [
        f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>framechain: {e(title)}</title>",
        f"<style>{CSS}</style></head><body>",
        f"<h1>framechain report: {e(title)}</h1>",
        f"<div class='verdict{' clean' if _clean(result) else ''}'>{e(result.verdict)}</div>",
        "<h2>Findings</h2>",
    ]
    if result.findings:
        parts.append(
            "<table><tr><th>fault</th><th>hop</th><th>camera</th><th>estimate</th><th>95% interval</th><th>share</th>"
            "<th>effect</th><th>confidence</th><th>strength</th><th>evidence</th><th>fix</th></tr>"
        )
        for c in (FindingView.of(f).cells() for f in result.findings):
            weak = " style='color:#777'" if c.strength != "strong" else ""
            b = breakable  # frame names wrap at their joints, so the table fits the page
            parts.append(
                f"<tr{weak}><td><b>{b(c.fault)}</b></td><td>{b(c.hop)}</td><td>{b(c.camera or '-')}</td>"
                f"<td>{b(c.estimate)}</td><td>{b(c.interval)}</td><td>{c.share}</td><td>{c.error}</td>"
                f"<td>{c.confidence}</td><td>{c.strength}</td><td>{b(c.evidence)}</td><td>{_code(c.fix)}</td></tr>"
            )
        parts.append("</table>")
    else:
        parts.append(f"<p>{_no_findings(result)}</p>")
    counts = result.counts()
    parts.append(
        f"<h2>Error</h2><p>{e(_error_sentence(result))} Observations: {counts['total']} total, "
        f"{counts['replayed']} replayed, rejected {e(str(counts['rejected'] or 'none'))}, {counts['stale']} stale.</p>"
    )
    parts.append("<h3>Per hop</h3><table><tr>" + "".join(f"<th>{e(c)}</th>" for c in HOP_COLUMNS) + "</tr>")
    parts += ["<tr>" + "".join(f"<td>{breakable(c)}</td>" for c in row) + "</tr>" for row in hop_rows(result)]
    parts.append("</table>")
    parts.append(f"<p class='legend'>Colours, in every plot and picture here, in Rerun and in the Foxglove export: "
                 f"{_legend_html()}</p>")
    if result.notes:
        parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{breakable(n)}</li>" for n in result.notes) + "</ul>")
    parts.append("<div class='plots'>")
    parts += [figure_html(fig) for fig in figures]
    parts.append("</div><h2>Provenance</h2><table>")
    parts += [f"<tr><th>{e(k)}</th><td>{breakable(v)}</td></tr>" for k, v in _provenance(result)]
    parts.append(
        "</table><p class='muted'>Written by framechain. Shares are Shapley values of the median error; "
        "confidence is the BIC weight of the finding against the next-best explanation; intervals are "
        "bootstrap 95% intervals over observations.</p></body></html>"
    )
    return "\n".join(parts)


def _legend_html() -> str:
    """The colour legend with a swatch of each colour of the palette: the meanings, then each fault's and hop's."""
    def swatch(rgb: tuple[int, int, int]) -> str:
        return f"<span style='color:{hex_color(rgb)}'>&#9679;</span>"

    meanings = "; ".join(f"{swatch(rgb)} {html.escape(name)}: {html.escape(meaning)}" for rgb, name, meaning in LEGEND)
    faults = ", ".join(f"{swatch(rgb)} {html.escape(fault)}" for fault, rgb in FAULT_COLORS.items())
    hops = ", ".join(f"{swatch(rgb)} {html.escape(hop.value)}" for hop, rgb in HOP_COLORS.items())
    return f"{meanings}. {html.escape(ERROR_LINE_LEGEND)}: {faults}; {html.escape(HOP_LEGEND)}: {hops}."


def _no_findings(result: Attribution) -> str:
    """What the findings section says when there are none."""
    if result.undetermined:
        return "No finding: what would decide is undetermined (the verdict above says what and why)."
    return "No fault beyond noise." if _clean(result) else "Nothing could be checked."


def _clean(result: Attribution) -> bool:
    """No finding to act on, nothing undetermined, and something could have been found (a log where nothing is
    observable is not clean)."""
    return (not any(f.actionable for f in result.findings) and not result.undetermined
            and not nothing_observable(result.bounds))


def _code(text: str) -> str:
    """Escape, and show `backticked` commands as code (both wrapping between words, long ones at their joints)."""
    pieces = text.split("`")
    return "".join(f"<code>{breakable(p, code=True)}</code>" if i % 2 else breakable(p) for i, p in enumerate(pieces))
