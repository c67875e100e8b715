"""Reports: one self-contained HTML page (plots embedded, no network) and Markdown beside its plots.

Order: the verdict in one sentence, the findings (estimates, intervals, fixes), the observation
accounting, then the pictures people would rather look at than read (error per hop over time,
error against robot speed, world points from above, the sensitivity of the fault found), what this
log can show, what the camera saw, then provenance (file, topics, frames, units, stamps,
configuration). Each section is written once (:mod:`framechain.sinks.document`) and rendered as both.
"""

from __future__ import annotations

import html
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from framechain.analysis.run import Run
from framechain.analysis.verdict.checks import nothing_observable
from framechain.analysis.verdict.findings import Attribution
from framechain.arrays import FloatArray
from framechain.sinks.checks_view import checks_section, curve_plots
from framechain.sinks.colors import (
    ERROR_LINE_LEGEND,
    FAULT_COLORS,
    HOP_COLORS,
    HOP_LEGEND,
    LEGEND,
    UNEXPLAINED_COLOR,
    hex_color,
    legend_text,
)
from framechain.sinks.document import (
    Block,
    Bullets,
    Callout,
    Column,
    Document,
    Figures,
    Heading,
    Html,
    ListItem,
    Paragraph,
    Section,
    table,
    write_document,
)
from framechain.sinks.evidence_files import inputs_record, write_attribution
from framechain.sinks.overlay import ImageOverlay
from framechain.sinks.plots import Figure, figure_png
from framechain.sinks.report_figures import after_label, make_figures, motion_figures
from framechain.sinks.text import FindingView, error_size, mm, observation_counts, position_said
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
    crops = image_crops(run)
    doc = report_document(result, pictures, checks, crops)
    figures = [*pictures, *checks, *(crop for _, shown in crops for crop in shown)]
    return write_document(doc, figures, out, formats, "report")


def report_document(result: Attribution, pictures: Sequence[Figure], checks: Sequence[Figure],
                    crops: Sequence[tuple[str, list[Figure]]]) -> Document:
    """The report of an attribution: its sections, written once for Markdown and HTML (what the camera saw comes
    before the provenance in HTML, after it in Markdown)."""
    title = Path(str(result.source.get("path", ""))).name or "episode"
    sections = [Section(None, (Callout(result.verdict, kind="verdict clean" if _clean(result) else "verdict"),)),
                _findings_section(result), _error_section(result)]
    if result.notes:
        sections.append(Section(Heading("Notes"), (Bullets(tuple(ListItem(n) for n in result.notes), joined=True),)))
    sections += [Section(None, (Figures(tuple(pictures), headed=True),)), checks_section(result, checks)]
    if crops:
        sections.append(replace(_crops_section(result, crops), only="html"))
    sections.append(_provenance_section(result))
    if crops:
        sections.append(replace(_crops_section(result, crops), only="md"))
    return Document(f"framechain report: {title}", f"framechain: {title}", tuple(sections), pipe="/")


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


def _crops_section(result: Attribution, crops: Sequence[tuple[str, list[Figure]]]) -> Section:
    blocks: list[Block] = [Paragraph(_crops_intro(result))]
    for title, shown in crops:
        blocks += [Heading(title, level=3), Figures(tuple(shown))]
    return Section(Heading("What the camera saw"), tuple(blocks), compact=True)


# -- text -------------------------------------------------------------------------------------
def _size(value: float | None, summary: dict[str, Any]) -> str:
    """An error summary's value in its unit: millimetres, or deg/s of a camera's rotation rate."""
    return error_size(value, str(summary.get("unit", "m")))


def _error_sentence(result: Attribution) -> str:
    """The error against the evidence and what the findings leave (or that there is no evidence to measure it)."""
    s = result.error_summary()
    if result.metric == "none":
        return "No error measured: the log has no evidence to measure the chain against."
    return (f"Against the {s['metric'].replace('_', ' ')}: median {_size(s['median'], s)}, p95 {_size(s['p95'], s)}, "
            f"max {_size(s['max'], s)}; {after_label(result)}: "
            f"median {_size(result.error_summary(result.error_after)['median'], s)}.")


HOP_COLUMNS = ("hop", "own departure med / p95 / max", "sample gap med / max", "stale", "attributed to it")


def hop_rows(result: Attribution) -> list[tuple[str, ...]]:
    """The per-hop summary as text cells (the CLI, Markdown and HTML share it)."""
    rows: list[tuple[str, ...]] = []
    for r in result.hop_summary():
        dep = r["departure_m"]
        gap = r["gap_ms"]
        faults = f" ({', '.join(r['faults'])})" if r["faults"] else ""
        rate = sum(f.error_m for f in result.findings if f.hop.value == r["hop"] and f.error_unit == "deg/s")
        # A camera's own motion measures rotation rates: nothing attributed is 0 deg/s there, not 0 mm.
        in_rates = rate or result.metric == "camera_motion"
        rows.append((
            r["hop"],
            "not logged" if dep is None else f"{mm(dep['median'])} / {mm(dep['p95'])} / {mm(dep['max'])}",
            "-" if gap is None else f"{gap['median']:.1f} / {gap['max']:.1f} ms",
            str(r["stale"]),
            f"{rate:.2f} deg/s{faults}" if in_rates else f"{mm(r['attributed_m'])}{faults}",
        ))
    return rows


def _provenance(result: Attribution) -> list[tuple[str, str]]:
    record = inputs_record(result)
    src = record["source"]
    frames, stamps = record["frames"], record["stamps"]
    cameras = [str(e["camera"]) for e in result.camera_motion] or [c["frame"] for c in record.get("cameras", ())]
    first, last = stamps["observations_first_ns"], stamps["observations_last_ns"]
    return [
        ("file", str(src.get("path", ""))),
        ("format", str(src.get("format", ""))),
        ("frames", f"{_camera_frames(cameras or [frames['camera']])}, body {frames['body']}, world {frames['world']}"),
        ("topics", json.dumps(record["topics"])),
        _cameras_row(result, record),
        ("units", "; ".join(f"{k}: {v}" for k, v in record["units"].items())),
        ("stamps", ("no observations logged" if first is None else f"observations from {first} to {last} ns")
         + f", {stamps['keyed_on']}"),
        ("metric", f"{record['metric']['name']}: {record['metric']['definition']}"),
        ("logged points", "; ".join(
            f"{role}: " + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in fates.items())
            for role, fates in record["evidence_alignment"].items()) or "none"),
        ("latency budget", f"{record['latency_budget_s'] * 1e3:g} ms"),
        ("observations", observation_counts(result)),
        ("configuration", json.dumps(record["configuration"])),
        ("seed", str(record["seed"])),
        ("framechain", str(record["framechain_version"])),
    ]


def _camera_frames(cameras: Sequence[str]) -> str:
    return f"camera {cameras[0]}" if len(cameras) == 1 else f"cameras {', '.join(cameras)}"


def _lens(camera: Mapping[str, Any]) -> str:
    return f"{camera['width']}x{camera['height']}, K {camera['K']}, distortion {camera['distortion_model']}"


def _cameras_row(result: Attribution, record: Mapping[str, Any]) -> tuple[str, str]:
    """Every camera's lens: as each camera's own motion was measured through, a rig's cameras, or the one camera."""
    if result.camera_motion:
        return ("cameras" if len(result.camera_motion) > 1 else "camera", "; ".join(
            f"{e['camera']}: declared on {e['declared_link'] or 'the world'}, {e['width_px']} px wide, focal "
            + (f"{e['focal_px']:g} px" if e.get("focal_px") else "unknown")
            + ("" if e.get("intrinsics_known", True) else " (guessed)") + _position_row(e)
            for e in result.camera_motion))
    if len(record.get("cameras", ())) > 1:
        return "cameras", "; ".join(f"{c['frame']}: {_lens(c)}" for c in record["cameras"])
    return "camera", _lens(record["camera"])


def _position_row(entry: Mapping[str, Any]) -> str:
    """A camera's position on its link, when it was not known and was fitted from its images."""
    said = position_said(entry)
    return f", position on {entry['position']['link']} not known: fitted from its images at {said}" if said else ""


#: The findings table: the evidence is a column in HTML, a list below the table in Markdown.
FINDING_COLUMNS = (Column("fault", "strong"), Column("hop", "wrap"), Column("camera", "wrap"),
                   Column("estimate", "wrap"), Column("95% interval", "wrap"), Column("share"), Column("effect"),
                   Column("confidence"), Column("strength"), Column("evidence", "wrap", only="html"),
                   Column("fix", "command"))


def _findings_section(result: Attribution) -> Section:
    if not result.findings:
        return Section(Heading("Findings"), (Paragraph(_no_findings(result)),))
    rows = [(c.fault, c.hop, c.camera or "-", c.estimate, c.interval, c.share, c.error, c.confidence, c.strength,
             c.evidence, c.fix) for c in (FindingView.of(f).cells() for f in result.findings)]
    evidence = Bullets(tuple(ListItem(f"{FindingView.of(f).on_camera()}: {f.evidence}", lead=f.fault.value)
                             for f in result.findings), only="md")
    return Section(Heading("Findings"), (
        table(FINDING_COLUMNS, rows, tone=lambda row: "" if row[8] == "strong" else "muted"), evidence))


def _error_section(result: Attribution) -> Section:
    """The error sentence (with the observation counts in HTML), the per-hop table and the colour legend."""
    observed = f" Observations: {observation_counts(result)}."
    legend = "Colours, in every plot and picture here, in Rerun and in the Foxglove export: "
    return Section(Heading("Error"), (
        Paragraph(_error_sentence(result), only="md"), Paragraph(_error_sentence(result) + observed, only="html",
                                                                 joined=True),
        Heading("Per hop", level=3), table([Column(c, "wrap") for c in HOP_COLUMNS], hop_rows(result), joined=True),
        Paragraph(legend + legend_text(), only="md"), Html(f"<p class='legend'>{legend}{_legend_html()}</p>")))


def _provenance_section(result: Attribution) -> Section:
    footer = ("Written by framechain. Shares are Shapley values of the median error; confidence is the BIC weight of "
              "the finding against the next-best explanation; intervals are bootstrap 95% intervals over "
              "observations.")
    return Section(Heading("Provenance", joined=True), (
        table([Column("", "key"), Column("", "wrap")], _provenance(result), joined=True),
        Paragraph(footer, muted=True, only="html", joined=True)))


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
