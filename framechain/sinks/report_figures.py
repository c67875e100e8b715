"""The report's pictures: the error over time and against robot speed, the world points from above, how fast the
fault found hurts as it grows, and each measured camera's rotation rate against forward kinematics.

Each is drawn from what the run computed (:class:`~framechain.analysis.run.Run`), and only where it shows what
its caption says.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from framechain.analysis.run import Run
from framechain.analysis.verdict.checks import tolerance_text
from framechain.analysis.verdict.findings import Attribution, Finding
from framechain.analysis.verdict.sensitivity import robot_speed, sensitivity
from framechain.arrays import FloatArray, IntArray
from framechain.catalogue import HopName
from framechain.sinks.colors import (
    AS_RUN_COLOR,
    BOUND_COLOR,
    CORRECTED_COLOR,
    FAULT_COLORS,
    HOP_COLORS,
    RECOMPUTED_COLOR,
    RECORDED_ERROR_COLOR,
    REFERENCE_COLOR,
    UNEXPLAINED_COLOR,
    hex_color,
)
from framechain.sinks.plots import Figure, figure_png, new_figure

__all__ = ["STILL_SPEED_M_S", "after_label", "make_figures", "motion_figures"]


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
              label=after_label(result))
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
              label=after_label(result))
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
    """Per measured camera, two figures: |rotation rate| over time from its images, from forward kinematics as
    declared and as fitted (a time offset shows as a shift, the picture of :mod:`framechain.sinks.rerun_egomotion`);
    and the misfit of the rate's components, as declared and as fitted (where a mount error shows too)."""
    out = []
    for curves in run.rotation_rates:
        t = curves.middle_ns * 1e-9
        name = "".join(c if c.isalnum() else "_" for c in curves.camera)
        fitted = f"{curves.link} shifted {curves.offset_s * 1e3:+.1f} ms, fitted mount"
        declared = f"forward kinematics of {curves.declared_link} as declared"
        fig, (ax,) = new_figure(6.4, 3.6, top="title")
        ax.plot(t, curves.measured.magnitude_deg_s, color="k", lw=1.6, label="from the images")
        ax.plot(t, curves.declared.magnitude_deg_s, color=hex_color(AS_RUN_COLOR), lw=1.0, label=declared)
        ax.plot(t, curves.fitted.magnitude_deg_s, color=hex_color(CORRECTED_COLOR), lw=1.0, ls="--", label=fitted)
        _legend_above(ax, curves.measured.magnitude_deg_s, curves.declared.magnitude_deg_s,
                      curves.fitted.magnitude_deg_s)
        _motion_axes(ax, "rotation rate (deg/s)", f"Camera {curves.camera}: its own motion against forward kinematics")
        out.append(figure_png(fig, f"rotation_rate_{name}",
                              f"Rotation rate of {curves.camera}: images against forward kinematics"))
        fig, (ax,) = new_figure(6.4, 3.6, top="title")
        before = np.linalg.norm(curves.measured.components_deg_s - curves.declared.components_deg_s, axis=1)
        after = np.linalg.norm(curves.measured.components_deg_s - curves.fitted.components_deg_s, axis=1)
        ax.plot(t, before, color=hex_color(AS_RUN_COLOR), lw=1.0, label=declared)
        ax.plot(t, after, color=hex_color(CORRECTED_COLOR), lw=1.0, label=fitted)
        _legend_above(ax, before, after)
        _motion_axes(ax, "misfit of the rate (deg/s)", f"Camera {curves.camera}: images minus forward kinematics")
        out.append(figure_png(fig, f"rotation_misfit_{name}",
                              f"Misfit of {curves.camera}'s rotation rate (every component: a mount error shows "
                              "here, not in the rate's size)"))
    return out


def _motion_axes(ax: Any, ylabel: str, title: str) -> None:
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.grid(True, alpha=0.3)


def _legend_above(ax: Any, *series: FloatArray) -> None:
    """The legend in room made above the curves (none of them drawn under it), the y axis from zero."""
    values = np.concatenate([s[np.isfinite(s)] for s in series])
    top = float(values.max()) if values.size else 1.0
    ax.set_ylim(0.0, 1.45 * top if top > 0 else 1.0)
    ax.legend(fontsize=7, loc="upper left")


def after_label(result: Attribution) -> str:
    """What the second error curve is: corrected data, or what the findings leave unexplained."""
    if result.metric in ("reference", "static_spread"):
        return "after correcting the recorded data"
    return "left unexplained by the findings"
