"""Reports: one self-contained HTML page (plots embedded, no network) and Markdown beside its plots.

Order: the verdict in one sentence, the findings (estimates, intervals, fixes), the observation
accounting, then the pictures people would rather look at than read (error per hop over time,
error against robot speed, world points from above, the sensitivity of the fault found), then
provenance (file, topics, frames, units, stamps, configuration).
"""

from __future__ import annotations

import base64
import html
import io
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from framechain.analysis.attribute import Attribution, Finding
from framechain.analysis.evidence import inputs_record, robot_speed, sensitivity
from framechain.timeline.arrays import FloatArray

_CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;max-width:1100px;color:#222;
line-height:1.45;padding:0 1em}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:1px solid #ddd;padding-bottom:.2em;margin-top:1.6em}
.verdict{font-size:1.2em;background:#fff6e5;border-left:5px solid #f0a020;padding:.7em 1em;margin:1em 0}
.verdict.clean{background:#eaf7ea;border-color:#3a3}
table{border-collapse:collapse;margin:.6em 0;font-size:.92em}
th,td{border:1px solid #ddd;padding:.35em .6em;text-align:left;vertical-align:top}
th{background:#f4f4f4}code{background:#f4f4f4;padding:.1em .3em;border-radius:3px;font-size:.9em;word-break:break-all}
.plots{display:grid;grid-template-columns:1fr 1fr;gap:1em}.plots figure{margin:0}
.plots img{width:100%;border:1px solid #eee}figcaption{font-size:.85em;color:#555}
.muted{color:#777;font-size:.9em}
"""


@dataclass(frozen=True)
class Figure:
    name: str
    caption: str
    png: bytes


def render_report(
    result: Attribution, out_dir: str | Path, *, formats: Sequence[str] = ("md", "html")
) -> dict[str, Path]:
    """Write report.md (with its PNGs) and/or report.html into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figures = make_figures(result)
    paths: dict[str, Path] = {}
    if "md" in formats:
        for fig in figures:
            (out / f"{fig.name}.png").write_bytes(fig.png)
        paths["md"] = out / "report.md"
        paths["md"].write_text(markdown(result, figures))
    if "html" in formats:
        paths["html"] = out / "report.html"
        paths["html"].write_text(html_page(result, figures))
    return paths


# -- figures ----------------------------------------------------------------------------------
def make_figures(result: Attribution) -> list[Figure]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figures: list[Figure] = []
    inputs = result.inputs
    t = (inputs.stamp_ns - inputs.stamp_ns.min()) * 1e-9 if len(inputs) else np.zeros(0)

    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=100)
    # The world error goes underneath, wide and pale, so a hop that carries all of it stays visible.
    ax.plot(t, result.error_before * 1e3, lw=4, color="k", alpha=0.25,
            label=f"world error ({result.metric.replace('_', ' ')})")
    for (hop, errors), style in zip(result.hop_errors.items(), ("-", "--", ":"), strict=False):
        ax.plot(t, errors * 1e3, lw=1.2, ls=style, label=f"{hop} (logged vs recomputed)")
    if result.findings:
        ax.plot(t, result.error_after * 1e3, lw=1, color="tab:green", ls="--", label=_after_label(result))
    ax.set_xlabel("time since first observation (s)")
    ax.set_ylabel("error (mm)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    figures.append(_png(fig, "error_per_hop", "Error per hop over time"))

    speed = robot_speed(result)
    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=100)
    ax.scatter(speed, result.error_before * 1e3, s=8, alpha=0.6, label="as recorded")
    if result.findings:
        ax.scatter(speed, result.error_after * 1e3, s=8, alpha=0.6, color="tab:green", label=_after_label(result))
    ax.set_xlabel("robot speed (m/s)")
    ax.set_ylabel("error (mm)")
    ax.set_title("A latency grows with speed", fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    figures.append(_png(fig, "error_vs_speed", "Error against robot speed (the latency signature)"))

    recomputed = _recomputed_world(result)
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=100)
    ax.scatter(recomputed[:, 0], recomputed[:, 1], s=8, label="recomputed from the log", alpha=0.7)
    ev = result.evidence_points
    if np.isfinite(ev).any() and result.metric != "static_spread":
        label = {"logged_hops": "as-run (robot's logged)", "target": "as-run target", "reference": "reference"}.get(
            result.metric, "evidence"
        )
        ax.scatter(ev[:, 0], ev[:, 1], s=8, marker="x", label=label, alpha=0.7)
    if result.findings and result.metric in ("reference", "static_spread"):
        ax.scatter(result.corrected_world[:, 0], result.corrected_world[:, 1], s=8, label="corrected", alpha=0.7)
    ax.set_xlabel(f"x in {result.config.frames.world} (m)")
    ax.set_ylabel(f"y in {result.config.frames.world} (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7)
    figures.append(_png(fig, "world_top_down", "World points from above"))

    if result.findings:
        top = result.findings[0]
        x, err, label = sensitivity(result, top)
        if x.size:
            fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=100)
            ax.plot(x, err * 1e3, color="tab:red")
            ax.axhline(10.0, color="k", ls="--", lw=1, label="1 cm gripper tolerance")
            ax.axvline(x[-1] / 1.5, color="tab:gray", ls=":", lw=1, label="found")
            ax.set_xlabel(label)
            ax.set_ylabel("median world error (mm)")
            ax.set_title(f"Sensitivity: {top.fault.value} at {top.hop.value}", fontsize=9)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
            figures.append(_png(fig, "sensitivity", f"How fast {top.fault.value} hurts on this episode"))
    return figures


def _after_label(result: Attribution) -> str:
    """What the second error curve is: corrected data, or what the findings leave unexplained."""
    if result.metric in ("reference", "static_spread"):
        return "after correcting the recorded data"
    return "left unexplained by the findings"


def _recomputed_world(result: Attribution) -> FloatArray:
    from framechain.analysis.chain_model import Perturbation, evaluate

    return evaluate(result.inputs, Perturbation())[2]


def _png(fig: Any, name: str, caption: str) -> Figure:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return Figure(name=name, caption=caption, png=buf.getvalue())


# -- text -------------------------------------------------------------------------------------
def estimate_text(f: Finding) -> str:
    parts = []
    for key, value in f.estimate.items():
        if key == "offset_s":
            parts.append(f"offset {float(value) * 1e3:+.1f} ms")
        elif key == "angle_deg":
            frame = f.estimate.get("axis_frame", "")
            parts.append(f"{float(value):.2f} deg about {_axis_text(f.estimate.get('axis', []))}"
                         + (f" of {frame}" if frame else ""))
        elif key in ("factor", "scale"):
            parts.append(f"{key} {float(value):.4g}")
        elif key in ("used", "meant", "hop", "variant"):
            parts.append(f"{key} {value}")
        elif key == "permutation":
            parts.append(f"permutation {value}")
        elif key == "edge":
            parts.append(f"edge {value[0]} -> {value[1]}")
    return "; ".join(parts)


def _axis_text(axis: Sequence[float]) -> str:
    """A principal axis by name (-y), any other as a rounded vector."""
    a = np.asarray(axis, dtype=float)
    if a.size == 3 and np.max(np.abs(a)) > 0.999:
        k = int(np.argmax(np.abs(a)))
        return f"{'+' if a[k] > 0 else '-'}{'xyz'[k]}"
    return str([round(float(v), 3) + 0.0 for v in a])  # + 0.0 drops negative zeros


def interval_text(f: Finding) -> str:
    out = []
    for key, (lo, hi) in f.interval.items():
        if key == "offset_s":
            out.append(f"{lo * 1e3:+.2f} .. {hi * 1e3:+.2f} ms")
        elif key == "angle_deg":
            out.append(f"{lo:.3f} .. {hi:.3f} deg")
        else:
            out.append(f"{lo:.5f} .. {hi:.5f}")
    return "; ".join(out) or "-"


HOP_COLUMNS = ("hop", "own departure med / p95 / max", "sample gap med / max", "stale", "attributed to it")


def hop_rows(result: Attribution) -> list[tuple[str, ...]]:
    """The per-hop summary as text cells (the CLI, Markdown and HTML share it)."""
    rows: list[tuple[str, ...]] = []
    for r in result.hop_summary():
        dep = r["departure_m"]
        gap = r["gap_ms"]
        faults = f" ({', '.join(r['faults'])})" if r["faults"] else ""
        rows.append((
            r["hop"],
            "not logged" if dep is None else f"{_mm(dep['median'])} / {_mm(dep['p95'])} / {_mm(dep['max'])}",
            "-" if gap is None else f"{gap['median']:.1f} / {gap['max']:.1f} ms",
            str(r["stale"]),
            f"{_mm(r['attributed_m'])}{faults}",
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
    s = result.error_summary()
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
            "| fault | hop | estimate | 95% interval | share | error (mm) | confidence | fix |",
            "| --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        for f in result.findings:
            lines.append(
                f"| {f.fault.value} | {f.hop.value} | {estimate_text(f)} | {interval_text(f)} | {f.share:.0%} | "
                f"{f.error_m * 1e3:.1f} | {f.confidence:.2f} | {f.fix.replace('|', '/')} |"
            )
        lines += [""] + [f"- **{f.fault.value}**: {f.evidence}" for f in result.findings]
    else:
        lines.append("No fault beyond noise.")
    lines += [
        "",
        "## Error",
        "",
        f"Against the {s['metric'].replace('_', ' ')}: median {_mm(s['median'])}, p95 {_mm(s['p95'])}, "
        f"max {_mm(s['max'])}; {_after_label(result)}: "
        f"median {_mm(result.error_summary(result.error_after)['median'])}.",
        "",
        "### Per hop",
        "",
        "| " + " | ".join(HOP_COLUMNS) + " |",
        "| " + " | ".join("---" for _ in HOP_COLUMNS) + " |",
        *("| " + " | ".join(row) + " |" for row in hop_rows(result)),
        "",
    ]
    if result.notes:
        lines += ["## Notes", "", *(f"- {n.replace('|', '/')}" for n in result.notes), ""]
    for fig in figures:
        lines += [f"### {fig.caption}", "", f"![{fig.caption}]({fig.name}.png)", ""]
    lines += ["## Provenance", "", "| | |", "| --- | --- |"]
    lines += [f"| {k} | {v.replace('|', '/')} |" for k, v in _provenance(result)]
    return "\n".join(lines) + "\n"


def _mm(value: float | None) -> str:
    return "n/a" if value is None else f"{value * 1e3:.1f} mm"


def html_page(result: Attribution, figures: Sequence[Figure]) -> str:
    e = html.escape
    s = result.error_summary()
    title = Path(str(result.source.get("path", ""))).name or "episode"
    parts = [
        f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>framechain: {e(title)}</title>",
        f"<style>{_CSS}</style></head><body>",
        f"<h1>framechain report: {e(title)}</h1>",
        f"<div class='verdict{'' if result.findings else ' clean'}'>{e(result.verdict)}</div>",
        "<h2>Findings</h2>",
    ]
    if result.findings:
        parts.append(
            "<table><tr><th>fault</th><th>hop</th><th>estimate</th><th>95% interval</th><th>share</th>"
            "<th>error</th><th>confidence</th><th>evidence</th><th>fix</th></tr>"
        )
        for f in result.findings:
            parts.append(
                f"<tr><td><b>{e(f.fault.value)}</b></td><td>{e(f.hop.value)}</td><td>{e(estimate_text(f))}</td>"
                f"<td>{e(interval_text(f))}</td><td>{f.share:.0%}</td><td>{f.error_m * 1e3:.1f} mm</td>"
                f"<td>{f.confidence:.2f}</td><td>{e(f.evidence)}</td><td>{_code(f.fix)}</td></tr>"
            )
        parts.append("</table>")
    else:
        parts.append("<p>No fault beyond noise.</p>")
    counts = result.counts()
    parts.append(
        f"<h2>Error</h2><p>Against the {e(s['metric'].replace('_', ' '))}: median {_mm(s['median'])}, "
        f"p95 {_mm(s['p95'])}, max {_mm(s['max'])}; {_after_label(result)}: median "
        f"{_mm(result.error_summary(result.error_after)['median'])}. Observations: {counts['total']} total, "
        f"{counts['replayed']} replayed, rejected {e(str(counts['rejected'] or 'none'))}, {counts['stale']} stale.</p>"
    )
    parts.append("<h3>Per hop</h3><table><tr>" + "".join(f"<th>{e(c)}</th>" for c in HOP_COLUMNS) + "</tr>")
    parts += ["<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in hop_rows(result)]
    parts.append("</table>")
    if result.notes:
        parts.append("<h2>Notes</h2><ul>" + "".join(f"<li>{e(n)}</li>" for n in result.notes) + "</ul>")
    parts.append("<div class='plots'>")
    for fig in figures:
        data = base64.b64encode(fig.png).decode("ascii")
        parts.append(
            f"<figure><img alt='{e(fig.caption)}' src='data:image/png;base64,{data}'>"
            f"<figcaption>{e(fig.caption)}</figcaption></figure>"
        )
    parts.append("</div><h2>Provenance</h2><table>")
    parts += [f"<tr><th>{e(k)}</th><td>{e(v)}</td></tr>" for k, v in _provenance(result)]
    parts.append(
        "</table><p class='muted'>Written by framechain. Shares are Shapley values of the median error; "
        "confidence is the BIC weight of the finding against the next-best explanation; intervals are "
        "bootstrap 95% intervals over observations.</p></body></html>"
    )
    return "\n".join(parts)


def _code(text: str) -> str:
    """Escape, and show `backticked` commands as code."""
    pieces = html.escape(text).split("`")
    return "".join(f"<code>{p}</code>" if i % 2 else p for i, p in enumerate(pieces))
