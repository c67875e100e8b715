"""Figures laid out by fixed margins and drawn once, laid out tightly only when a text is cut off; the
report's own figures fit the fixed margins (the draw that tight_layout costs is saved)."""

from __future__ import annotations

import io
import os
import pickle
import subprocess
import sys
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
    draws: list[Any] = []
    original = plots._png
    monkeypatch.setattr(plots, "_png", lambda f: draws.append(f) or original(f))
    figure = figure_png(fig, "fits", "a caption")
    assert len(draws) == 1
    assert draws[0].subplotpars.left == pytest.approx(LEFT_IN / 6.4)
    assert _outside(draws[0]) == []
    image = Image.open(io.BytesIO(figure.png))
    assert image.size == (640, 360)


def _drawn_by_figure_png(monkeypatch: pytest.MonkeyPatch, fig: Any) -> Any:
    """The matplotlib figure figure_png drew and encoded last."""
    draws: list[Any] = []
    original = plots._png
    monkeypatch.setattr(plots, "_png", lambda f: draws.append(f) or original(f))
    figure_png(fig, "name", "")
    return draws[-1]


def test_long_tick_labels_are_laid_out_again_until_nothing_is_cut_off(monkeypatch: pytest.MonkeyPatch) -> None:
    fig, (ax_status, ax_fault) = new_figure(9.6, 3.4, columns=2, top="title")
    names = ["wrong_camera_frame at camera_to_body", "missing_rotation at camera_to_body"]
    ax_status.barh(["ok", "fault"], [3, 4])
    ax_fault.barh(names, [2, 5])
    ax_fault.set_title("Faults across the fleet")
    as_made = plots.draw(fig.sketch)
    as_made.canvas.draw()
    assert _outside(as_made)  # the fixed margins cut the long names off (and into the left axes)
    drawn = _drawn_by_figure_png(monkeypatch, fig)
    assert _outside(drawn) == []
    assert drawn.subplotpars.left != pytest.approx(LEFT_IN / 9.6)


def test_a_wide_right_axes_label_reaching_into_its_neighbour_is_seen(monkeypatch: pytest.MonkeyPatch) -> None:
    fig, (left, right) = new_figure(6.4, 3.4, columns=2, top="suptitle")
    left.plot([0, 1], [0, 1])
    right.plot([0, 1], [123456789.0, 987654321.0])
    right.ticklabel_format(axis="y", style="plain", useOffset=False)
    fig.suptitle("two columns")
    as_made = plots.draw(fig.sketch)
    as_made.canvas.draw()
    assert _outside(as_made)
    assert _outside(_drawn_by_figure_png(monkeypatch, fig)) == []


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


def _sketches() -> list[Any]:
    """Two figures as the report and the fleet report make them."""
    fig, (ax,) = new_figure(6.4, 3.6, top="title")
    rng = np.random.default_rng(1)
    ax.plot(rng.normal(size=500), rng.normal(size=500), ls="none", marker="o", ms=2.8, label="points")
    ax.set_title("a scatter")
    ax.legend(fontsize=7)
    wide, (ax_status, ax_fault) = new_figure(9.6, 3.4, columns=2, top="title")
    ax_status.barh(["ok", "fault"], [3, 4])
    ax_fault.barh(["wrong_camera_frame at camera_to_body", "missing_rotation at camera_to_body"], [2, 5])
    return [fig, wide]


def test_renderer_processes_draw_the_same_pngs_as_this_process(monkeypatch: pytest.MonkeyPatch) -> None:
    here = [figure_png(fig, f"f{i}", "").png for i, fig in enumerate(_sketches())]
    assert all(png.startswith(b"\x89PNG") for png in here)

    def not_here(sketch: Any) -> bytes:
        raise AssertionError("drawn in the test's process, not by a renderer")

    monkeypatch.setattr(plots, "render_png", not_here)
    with plots.renderers(2):
        figures = [figure_png(fig, f"f{i}", "") for i, fig in enumerate(_sketches())]
        assert [f.png for f in figures] == here


def test_a_renderer_and_its_twin_draw_the_figures_between_them(monkeypatch: pytest.MonkeyPatch) -> None:
    here = [figure_png(fig, f"f{i}", "").png for i, fig in enumerate(_sketches() * 3)]
    monkeypatch.setattr(plots, "render_png", lambda sketch: pytest.fail("drawn in the test's process"))
    sent: list[int] = []
    serve = plots._Pool._serve

    class Counted:  # a channel's sketch stream, counting the sketches sent on it
        def __init__(self, stream: Any) -> None:
            self.stream = stream
            sent.append(0)
            self.number = len(sent) - 1

        def write(self, data: bytes) -> int:
            return int(self.stream.write(data))

        def flush(self) -> None:
            sent[self.number] += 1
            self.stream.flush()

    monkeypatch.setattr(plots._Pool, "_serve", lambda pool, sketches, replies: serve(pool, Counted(sketches), replies))
    with plots.renderers(2, twins=True):
        pool = plots._running[0]
        assert len(pool._processes) == 1  # one process started; its twin is forked from it
        figures = [figure_png(fig, f"f{i}", "") for i, fig in enumerate(_sketches() * 3)]
        assert [f.png for f in figures] == here
    assert len(sent) == 2
    assert min(sent) >= 1  # both channels drew
    assert sum(sent) == len(here)
    assert pool._processes[0].returncode == 0


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (read from /proc: no procps needed)."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:  # ended meanwhile
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(entry.name))
    return out


def test_a_twin_does_not_hold_its_renderer_s_input_open() -> None:
    """Were the twin to keep the renderer's stdin, the command's writes to a renderer that died would fill the pipe
    and wait instead of failing: its figures are drawn here, and the block ends."""
    fig = _sketches()[0]
    here = figure_png(fig, "f", "").png
    with plots.renderers(2, twins=True):
        pool = plots._running[0]
        assert figure_png(fig, "f", "").png == here  # warm: the twin is forked
        renderer = pool._processes[0]
        (pid,) = _children(renderer.pid)
        stdin = os.readlink(f"/proc/{renderer.pid}/fd/0")
        assert os.readlink(f"/proc/{pid}/fd/0") != stdin
        renderer.kill()
        renderer.wait()
        assert all(figure_png(big, f"f{i}", "").png for i, big in enumerate([fig] * 40))


def test_a_twin_that_died_leaves_its_figures_to_this_process() -> None:
    import signal

    fig = _sketches()[0]
    here = figure_png(fig, "f", "").png
    with plots.renderers(2, twins=True):
        pool = plots._running[0]
        assert figure_png(fig, "f", "").png == here  # the renderer is warm: its twin is forked
        twin = _children(pool._processes[0].pid)
        assert len(twin) == 1
        os.kill(twin[0], signal.SIGKILL)
        assert all(figure_png(fig, f"f{i}", "").png == here for i in range(4))


def test_a_renderer_ends_at_the_end_of_its_input_without_the_interpreter_s_teardown() -> None:
    # An exit handler registered before the renderer serves stands for the teardown the command would wait for.
    program = ("import atexit, sys\n"
               "atexit.register(lambda: sys.stderr.write('torn down'))\n"
               "from framechain.sinks.plots import serve_renderer\n"
               "serve_renderer()\n"
               "sys.stderr.write('returned')\n")
    sketch = _sketches()[0].sketch
    request = pickle.dumps(sketch, protocol=pickle.HIGHEST_PROTOCOL)
    done = subprocess.run([sys.executable, "-c", program], input=request, capture_output=True, timeout=120,
                          check=False)
    assert done.returncode == 0
    assert b"torn down" not in done.stderr
    assert b"returned" not in done.stderr
    drawn, png = pickle.loads(done.stdout)
    assert drawn
    assert png == plots.render_png(sketch)


def test_the_figures_of_a_renderer_that_died_are_drawn_here() -> None:
    fig, = _sketches()[:1]
    here = figure_png(fig, "f", "").png
    with plots.renderers(1):
        for process in plots._running[0]._processes:
            process.kill()
            process.wait()
        assert figure_png(fig, "f", "").png == here


def test_the_number_of_renderers_is_checked(monkeypatch: pytest.MonkeyPatch) -> None:
    from framechain.errors import FramechainError

    monkeypatch.setenv(plots.RENDERERS_VARIABLE, "two")
    with pytest.raises(FramechainError, match="FRAMECHAIN_RENDERERS='two'"), plots.renderers():
        pass


def test_the_number_of_renderers_is_the_usual_one_unless_the_variable_says(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(plots.RENDERERS_VARIABLE, raising=False)
    with plots.renderers(usual=1, start_now=False):
        assert plots._running[0]._workers == 1
    with plots.renderers(start_now=False):
        assert plots._running[0]._workers == plots.RENDERERS == 2
    monkeypatch.setenv(plots.RENDERERS_VARIABLE, "3")
    with plots.renderers(usual=1, start_now=False):
        assert plots._running[0]._workers == 3
    monkeypatch.setenv(plots.RENDERERS_VARIABLE, "0")
    with plots.renderers(usual=1):
        assert not plots._running  # none: figures drawn here


def test_a_renderer_that_cannot_start_leaves_the_figures_to_this_process(monkeypatch: pytest.MonkeyPatch,
                                                                          capfd: pytest.CaptureFixture[str]) -> None:
    fig = _sketches()[0]
    here = figure_png(fig, "f", "").png
    monkeypatch.setattr(plots, "_RENDERER_MAIN", plots._RENDERER_MAIN.replace("framechain.sinks.plots", "no_such_pkg"))
    with plots.renderers(1):
        assert figure_png(fig, "f", "").png == here
    assert capfd.readouterr().err == ""  # no traceback from the renderer that could not import framechain


def test_renderers_started_later_start_when_asked_or_at_the_first_figure() -> None:
    fig = _sketches()[0]
    here = figure_png(fig, "f", "").png
    with plots.renderers(1, start_now=False):
        pool = plots._running[0]
        assert not pool.started
        plots.start_renderers()
        assert pool.started
        processes = list(pool._processes)
        plots.start_renderers()  # once only
        assert pool._processes == processes
        assert figure_png(fig, "f", "").png == here
    with plots.renderers(1, start_now=False):
        assert figure_png(fig, "f", "").png == here  # a figure asked for first starts them
        assert plots._running[0].started
    plots.start_renderers()  # outside a block: nothing to start
    assert not plots._running
