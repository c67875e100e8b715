"""Figures laid out by fixed margins and drawn once, laid out tightly only when a text is cut off; the
report's own figures fit the fixed margins (the draw that tight_layout costs is saved)."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from framechain import pipeline
from framechain.catalogue import Fault
from framechain.sim import InjectedFault, SceneSpec, generate
from framechain.sinks import plots
from framechain.sinks.plots import LEFT_IN, figure_png, new_figure
from framechain.sinks.report import render_report


def _outside(fig: Any) -> list[str]:
    """Independently of plots: every drawn tick label and axis label whose box leaves the figure, or
    reaches into another axes."""
    renderer = fig.canvas.get_renderer()
    w, h = fig.bbox.width, fig.bbox.height
    out = []
    for ax in fig.axes:
        labels = [ax.xaxis.label, ax.yaxis.label, ax.title]
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            labels += [t for loc, t in zip(axis.get_majorticklocs(), axis.get_majorticklabels(), strict=True)
                       if lo <= loc <= hi]
        for text in labels:
            if not text.get_text():
                continue
            box = text.get_window_extent(renderer)
            leaves = box.x0 < -1 or box.y0 < -1 or box.x1 > w + 1 or box.y1 > h + 1
            if leaves or any(box.overlaps(o.get_window_extent(renderer)) for o in fig.axes if o is not ax):
                out.append(text.get_text())
    return out


def test_a_figure_whose_labels_fit_keeps_its_margins_and_is_drawn_once(monkeypatch: pytest.MonkeyPatch) -> None:
    fig, (ax,) = new_figure(6.4, 3.6)
    ax.plot(np.arange(100.0), np.arange(100.0) * 12.5)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("error (mm)")
    draws = []
    original = plots._png
    monkeypatch.setattr(plots, "_png", lambda f: draws.append(1) or original(f))
    figure = figure_png(fig, "fits", "a caption")
    assert draws == [1]
    assert fig.subplotpars.left == pytest.approx(LEFT_IN / 6.4)
    assert _outside(fig) == []
    image = Image.open(io.BytesIO(figure.png))
    assert image.size == (640, 360)


def test_long_tick_labels_are_laid_out_again_until_nothing_is_cut_off() -> None:
    fig, (ax_status, ax_fault) = new_figure(9.6, 3.4, columns=2, top="title")
    names = ["wrong_camera_frame at camera_to_body", "missing_rotation at camera_to_body"]
    ax_status.barh(["ok", "fault"], [3, 4])
    ax_fault.barh(names, [2, 5])
    ax_fault.set_title("Faults across the fleet")
    fig.canvas.draw()
    assert _outside(fig)  # the fixed margins cut the long names off (and into the left axes)
    figure_png(fig, "fleet", "")
    assert _outside(fig) == []
    assert fig.subplotpars.left != pytest.approx(LEFT_IN / 9.6)


def test_a_wide_right_axes_label_reaching_into_its_neighbour_is_seen() -> None:
    fig, (left, right) = new_figure(6.4, 3.4, columns=2, top="suptitle")
    left.plot([0, 1], [0, 1])
    right.plot([0, 1], [123456789.0, 987654321.0])
    right.ticklabel_format(axis="y", style="plain", useOffset=False)
    fig.suptitle("two columns")
    fig.canvas.draw()
    assert _outside(fig)
    figure_png(fig, "wide", "")
    assert _outside(fig) == []


def test_the_report_s_figures_fit_the_fixed_margins(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    scene = generate(SceneSpec(seed=6, duration_s=5.0, evidence="static",
                               faults=(InjectedFault(Fault.LATENCY, "data", {"offset_s": 0.030}),)))
    run = pipeline.run(scene.timeline, scene.chain, bootstrap=0)
    laid_out: list[Any] = []
    drawn: list[Any] = []
    original = plots._png

    def spy(fig: Any) -> bytes:
        drawn.append(fig)
        png = original(fig)
        if _outside(fig):
            laid_out.append(fig)
        return png

    monkeypatch.setattr(plots, "_png", spy)
    render_report(run, tmp_path, formats=("md",))
    assert len(drawn) >= 6  # error per hop, against speed, from above, sensitivity and the curves
    assert laid_out == []
    assert len(set(map(id, drawn))) == len(drawn)  # each drawn once
