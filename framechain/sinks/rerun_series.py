"""The numbers and words of a Rerun recording: every hop's point recomputed and as run, the error arrows,
per-hop error and time-gap series, the error the findings explain, the findings, rejections and stale
observations, and a summary."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from framechain.analysis.verdict.findings import Attribution
from framechain.arrays import FloatArray, IntArray, rows_of
from framechain.catalogue import HopName
from framechain.replay import REPLAYED, ReplayResult
from framechain.sinks.colors import (
    AS_RUN_COLOR,
    CORRECTED_COLOR,
    ERROR_COLOR,
    HOP_COLORS,
    RECOMPUTED_COLOR,
    RECORDED_ERROR_COLOR,
    REFERENCE_COLOR,
    legend_text,
)
from framechain.sinks.document import (
    Block,
    Bullets,
    Callout,
    Column,
    Document,
    Heading,
    ListItem,
    Paragraph,
    Section,
    markdown,
    table,
)
from framechain.sinks.rerun_common import (
    REPLAY_FRAME_SUFFIX,
    CameraView,
    Clock,
    RerunOptions,
)
from framechain.sinks.text import FindingView

if TYPE_CHECKING:
    import rerun as rr


def log_points(
    rec: rr.RecordingStream, result: ReplayResult, clock: Clock, as_run: Mapping[str, FloatArray], opts: RerunOptions,
    rows: dict[str, int], views: list[CameraView] | None = None, error_color: tuple[int, int, int] = ERROR_COLOR,
) -> None:
    """Recomputed and as-run points at every hop, the reference, arrows recomputed -> as-run (camera-frame
    points per camera of a rig, ``views``) in ``error_color``: the colour of the finding that explains them, as
    the line between the two points in the image (red when none does)."""
    import rerun as rr

    frames = result.frames
    hop_frame = {"camera": frames.camera + REPLAY_FRAME_SUFFIX, "body": frames.body + REPLAY_FRAME_SUFFIX,
                 "world": frames.world, "target": frames.world}
    rig = [v for v in views or [] if v.rig]
    recomputed = {"camera": result.p_cam, "body": result.p_body, "world": result.p_world,
                  "target": result.p_world}
    obs_id = result.observations.obs_id
    radius = opts.point_radius_m

    def send_points(entity: str, frame: str, xyz: FloatArray, color: tuple[int, int, int], what: str) -> None:
        sel = np.flatnonzero(np.isfinite(xyz).all(axis=1))
        if sel.size == 0:
            return
        rec.log(entity, rr.CoordinateFrame(frame), static=True)
        rec.send_columns(
            entity, indexes=clock.obs_indexes(result, sel),
            columns=rr.Points3D.columns(
                positions=xyz[sel], colors=np.tile(np.array(color, dtype=np.uint8), (sel.size, 1)),
                radii=np.full(sel.size, radius, dtype=np.float32),
                labels=[f"obs {i} {what}" for i in obs_id[sel].tolist()],
                show_labels=[False] * sel.size,  # on hover: several overlap at one point
            ),
        )
        rows[entity] = int(sel.size)

    for view in rig:  # each camera's points in its own frame
        for name, xyz, color in (("recomputed", result.p_cam, RECOMPUTED_COLOR), ("as_run", as_run["camera"],
                                                                                  AS_RUN_COLOR)):
            mine = np.full_like(xyz, np.nan)
            mine[view.rows] = xyz[view.rows]
            send_points(view.entity(f"/points/{name}/camera", ""), view.frame + REPLAY_FRAME_SUFFIX, mine, color,
                        f"{name.replace('_', '-')} (camera)")
    for leaf in ("camera", "body", "world") if not rig else ("body", "world"):
        send_points(f"/points/recomputed/{leaf}", hop_frame[leaf], recomputed[leaf], RECOMPUTED_COLOR,
                    f"recomputed ({leaf})")
    for leaf in ("camera", "body", "world", "target") if not rig else ("body", "world", "target"):
        logged = as_run[leaf]
        send_points(f"/points/as_run/{leaf}", hop_frame[leaf], logged, AS_RUN_COLOR, f"as-run ({leaf})")
        _send_arrows(rec, result, clock, f"/points/error/{leaf}", hop_frame[leaf], recomputed[leaf], logged,
                     error_color, radius / 4, rows)
    send_points("/points/reference/matched", frames.world, as_run["reference"], REFERENCE_COLOR, "reference")


def _send_arrows(rec: rr.RecordingStream, result: ReplayResult, clock: Clock, entity: str, frame: str,
                 start: FloatArray, end: FloatArray, color: tuple[int, int, int], radius: float,
                 rows: dict[str, int]) -> None:
    """Arrows ``start -> end`` (a hop's recomputed point to its as-run one) where both are, labelled in mm."""
    import rerun as rr

    both = np.flatnonzero(np.isfinite(end).all(axis=1) & np.isfinite(start).all(axis=1))
    if both.size == 0:
        return
    rec.log(entity, rr.CoordinateFrame(frame), static=True)
    delta = end[both] - start[both]
    rec.send_columns(
        entity, indexes=clock.obs_indexes(result, both),
        columns=rr.Arrows3D.columns(
            origins=start[both], vectors=delta, colors=np.tile(np.array(color, dtype=np.uint8), (both.size, 1)),
            radii=np.full(both.size, radius, dtype=np.float32),
            labels=[f"{np.linalg.norm(d) * 1e3:.1f} mm" for d in delta],
            show_labels=[False] * both.size,  # on hover: the 3D view's labels name the chain's frames alone
        ),
    )
    rows[entity] = int(both.size)


def log_series(
    rec: rr.RecordingStream, result: ReplayResult, clock: Clock, as_run: Mapping[str, FloatArray],
    rows: dict[str, int],
) -> None:
    """Each hop's own error (mm) where as-run exists (:func:`hop_own_errors`), the world point against a target or
    reference, and per-hop time gap (ms), one row per observation."""
    ok = result.replayed
    for hop, err in hop_own_errors(result, as_run).items():
        sel = np.flatnonzero(ok & np.isfinite(err))
        _send_series(rec, result, clock, f"/series/error_mm/{hop.value}", sel, err[sel] * 1e3,
                     f"{hop.value}: this hop's own error (mm)", HOP_COLORS[hop], rows)
    for leaf, color in (("target", AS_RUN_COLOR), ("reference", REFERENCE_COLOR)):
        err = np.linalg.norm(as_run[leaf] - result.p_world, axis=1)
        sel = np.flatnonzero(ok & np.isfinite(err))
        _send_series(rec, result, clock, f"/series/error_mm/{leaf}", sel, err[sel] * 1e3, f"world vs {leaf} (mm)",
                     color, rows)

    hops = result.hops
    for hop in HopName:
        sel_rows = np.flatnonzero((hops.hop == hop.value) & (hops.status == REPLAYED))
        obs_rows = rows_of(result.observations.obs_id, hops.obs_id[sel_rows])
        order = np.argsort(obs_rows, kind="stable")
        _send_series(rec, result, clock, f"/series/gap_ms/{hop.value}", obs_rows[order],
                     hops.gap_ns[sel_rows][order] / 1e6, f"{hop.value} gap (ms)", HOP_COLORS[hop], rows)


def hop_own_errors(result: ReplayResult, as_run: Mapping[str, FloatArray]) -> dict[HopName, FloatArray]:
    """Per hop, (N,) metres: the as-run point at the hop's output against the hop (the transform the replay used)
    applied to the as-run point at its input, as the report's hop departure does: an error made upstream is not
    counted again. Where the robot logged no input to a hop, its input is the earlier logged stage carried
    through (the recomputed camera point where none was logged). NaN where the output was not logged."""
    def apply(transform: FloatArray, p: FloatArray) -> FloatArray:
        out: FloatArray = np.einsum("nij,nj->ni", transform[:, :3, :3], p) + transform[:, :3, 3]
        return out

    def logged_or(leaf: str, fallback: FloatArray) -> FloatArray:
        out: FloatArray = np.where(np.isfinite(as_run[leaf]).all(axis=1, keepdims=True), as_run[leaf], fallback)
        return out

    out = {HopName.PIXEL_TO_CAMERA: np.linalg.norm(as_run["camera"] - result.p_cam, axis=1)}
    body = apply(result.body_from_cam.matrix(), logged_or("camera", result.p_cam))
    out[HopName.CAMERA_TO_BODY] = np.linalg.norm(as_run["body"] - body, axis=1)
    body = logged_or("body", body)
    out[HopName.BODY_TO_WORLD] = np.linalg.norm(as_run["world"] - apply(result.world_from_body.matrix(), body), axis=1)
    return out


def log_explained_error(rec: rr.RecordingStream, result: ReplayResult, clock: Clock, attribution: Attribution,
                        rows: dict[str, int]) -> None:
    """The error the findings explain, per observation the attribution used (``/series/error_mm/world_error``: the
    world point against its evidence, e.g. a static target's own position), and what remains once every finding is
    corrected (``/series/error_mm/corrected``)."""
    if attribution.metric in ("camera_motion", "none"):  # a rotation-rate residual, or nothing measured
        return
    what = {"logged_hops": "the as-run world point", "target": "the as-run target", "reference": "the reference",
            "static_spread": "the static target's own position", "cross_camera": "the other cameras' sightings"}
    obs_rows = rows_of(result.observations.obs_id, attribution.inputs.obs_id)
    series = [("world_error", attribution.error_before, RECORDED_ERROR_COLOR,
               f"world error against {what.get(attribution.metric, 'the evidence')} (mm)")]
    if attribution.findings:
        series.append(("corrected", attribution.error_after, CORRECTED_COLOR, "world error, findings corrected (mm)"))
    for leaf, values, color, name in series:
        have = np.flatnonzero((obs_rows >= 0) & np.isfinite(values))
        have = have[np.argsort(obs_rows[have], kind="stable")]
        # the world error underneath, wide and pale (as in the report): a hop that carries all of it stays visible
        _send_series(rec, result, clock, f"/series/error_mm/{leaf}", obs_rows[have], values[have] * 1e3, name,
                     color, rows, under=leaf == "world_error")


def _send_series(rec: rr.RecordingStream, result: ReplayResult, clock: Clock, entity: str, sel: IntArray,
                 values: FloatArray, name: str, color: tuple[int, int, int], rows: dict[str, int], *,
                 under: bool = False) -> None:
    """One scalar series over observation rows ``sel`` (lines and points: a single observation still shows;
    ``under``: wide and translucent, for a series others may lie on)."""
    import rerun as rr

    if sel.size == 0:
        return
    rgba = (*color, 90 if under else 255)
    rec.log(entity, rr.SeriesLines(names=[name], colors=[rgba], widths=[5.0] if under else None), rr.SeriesPoints(
        names=[name], colors=[rgba], marker_sizes=[2.0]), static=True)
    rec.send_columns(entity, indexes=clock.obs_indexes(result, sel), columns=rr.Scalars.columns(scalars=values))
    rows[entity] = int(sel.size)


def log_text(rec: rr.RecordingStream, result: ReplayResult, clock: Clock, findings: Iterable[FindingView],
             rows: dict[str, int], *, start_ns: int | None = None, verdict: str = "",
             measured_instead: str = "") -> None:
    """Findings (at the first observation; without observations at ``start_ns``, the log's first moment;
    without findings, ``/log/verdict``: why there are none), rejected and stale observations, and a summary
    (``measured_instead``: what a run without observations measured, in place of their counts)."""
    import rerun as rr

    obs = result.observations
    budget_ms = result.latency_budget_ns / 1e6
    found = list(findings)
    entries = rr.TextLog.columns(text=[f.text() for f in found], level=[rr.TextLogLevel.ERROR] * len(found))
    if not found and verdict and len(obs):
        first = np.array([int(np.argmin(obs.stamp_ns))], dtype=np.int64)
        rec.send_columns("/log/verdict", indexes=clock.obs_indexes(result, first),
                         columns=rr.TextLog.columns(text=[verdict], level=[rr.TextLogLevel.INFO]))
        rows["/log/verdict"] = 1
    if found and len(obs):
        first = np.full(len(found), int(np.argmin(obs.stamp_ns)), dtype=np.int64)
        rec.send_columns("/log/findings", indexes=clock.obs_indexes(result, first), columns=entries)
        rows["/log/findings"] = len(found)
    elif found and start_ns is not None:
        # An episode measured by its cameras' motion: the viewer's text log view shows timed entries, not static ones.
        rec.send_columns("/log/findings", indexes=clock.columns(np.full(len(found), start_ns)),
                         columns=entries)
        rows["/log/findings"] = len(found)
    elif found:
        rec.log("/log/findings", rr.TextLog("\n".join(f.text() for f in found), level=rr.TextLogLevel.ERROR),
                static=True)
        rows["/log/findings"] = 1
    rejected = np.flatnonzero(~result.replayed)
    if rejected.size:
        texts = [_rejection_text(result, int(i)) for i in rejected]
        rec.send_columns("/log/rejected", indexes=clock.obs_indexes(result, rejected),
                         columns=rr.TextLog.columns(text=texts, level=[rr.TextLogLevel.WARN] * rejected.size))
        rows["/log/rejected"] = int(rejected.size)
    stale = np.flatnonzero(result.stale & result.replayed)
    if stale.size:
        hops = result.hops
        gaps = np.zeros((len(obs), len(HopName)), dtype=np.int64)
        for j, hop in enumerate(HopName):
            sel = np.flatnonzero(hops.hop == hop.value)
            gaps[rows_of(result.observations.obs_id, hops.obs_id[sel]), j] = hops.gap_ns[sel]
        texts = []
        for i in stale.tolist():
            worst = int(np.argmax(np.abs(gaps[i])))
            texts.append(f"obs {int(obs.obs_id[i])} stale: {list(HopName)[worst].value} used a sample "
                         f"{gaps[i, worst] / 1e6:+.1f} ms from the observation stamp (budget {budget_ms:g} ms)")
        rec.send_columns("/log/stale", indexes=clock.obs_indexes(result, stale),
                         columns=rr.TextLog.columns(text=texts, level=[rr.TextLogLevel.INFO] * stale.size))
        rows["/log/stale"] = int(stale.size)
    summary = summary_markdown(result, found, verdict, measured_instead)
    rec.log("/summary", rr.TextDocument(summary, media_type=rr.MediaType.MARKDOWN),
            static=True)
    rows["/summary"] = 1


def _rejection_text(result: ReplayResult, i: int) -> str:
    obs = result.observations
    reason = str(result.status[i])
    frames = result.frames
    detail = ""
    if reason in ("extrapolation", "missing_edge"):
        for name, lookup in (("camera_to_body", result.body_from_cam), ("body_to_world", result.world_from_body)):
            if not bool(lookup.ok[i]):
                detail = f" on {name} ({lookup.target} <- {lookup.source})"
                break
    elif reason in ("no_depth", "depth_invalid"):
        detail = f" (depth {result.depth_m[i]:.3g} m)" if np.isfinite(result.depth_m[i]) else ""
    elif reason == "outside_image":
        detail = f" (pixel {obs.u[i]:.1f}, {obs.v[i]:.1f})"
    elif reason == "no_camera_info":
        detail = f" (no CameraInfo for {frames.camera})"
    return f"obs {int(obs.obs_id[i])} {obs.label[i]} rejected: {reason}{detail}".replace("  ", " ")


def summary_markdown(result: ReplayResult, findings: Sequence[FindingView] = (), verdict: str = "",
                     measured_instead: str = "") -> str:
    """The verdict, counts (total, replayed, rejected per reason, stale; or, for a run without observations,
    ``measured_instead``), findings and the colour legend as Markdown."""
    counts = result.counts()
    rejected = counts["rejected"]
    assert isinstance(rejected, dict)
    frames = result.frames
    rows = [("total", str(counts["total"])), ("replayed", str(counts["replayed"])),
            *((f"rejected: {reason}", str(n)) for reason, n in sorted(rejected.items())),
            ("stale (replayed)", str(counts["stale"]))]
    blocks: list[Block] = [Callout(verdict, kind="verdict")] if verdict else []
    blocks += [Paragraph(f"Chain: `{frames.camera}` -> `{frames.body}` -> `{frames.world}`; "
                         f"latency budget {result.latency_budget_ns / 1e6:g} ms."),
               Paragraph(f"Observations: {measured_instead}.") if measured_instead else
               table([Column("observations"), Column("count", right=True)], rows)]
    if findings:
        blocks += [Heading("Findings"), Bullets(tuple(ListItem(f.text()) for f in findings))]
    blocks += [Heading("Colours"), Paragraph(legend_text())]
    return markdown(Document("framechain replay", "", (Section(None, tuple(blocks)),)))
