"""Matplotlib figures (Agg, files only): one way to make a figure, lay it out and encode it as PNG.

A figure is laid out by fixed margins in inches, wide enough for the report's axis labels, and drawn
once. ``tight_layout`` would fit each figure's margins exactly, but it draws every tick label once
more to measure it: 40% of a figure's cost (a second of a report's). After the one draw,
:func:`figure_png` checks that no title, axis label or tick label fell outside the figure or onto
another axes, and only then lays the figure out tightly and draws it again.

A figure is made as a :class:`Sketch`: the matplotlib calls made on it, recorded as plain data, so it
can be drawn in another process. Drawing a report's figures is matplotlib's Python (about 1.0 s on
the 10-minute benchmark log) after its import (0.5 s). A command that writes a report runs
:data:`RENDERERS` renderer processes (:func:`renderers`), started once its log is read (:func:`start_renderers`):
each imports matplotlib at a low priority while the command replays and attributes on one core, then draws the
sketches it is sent (pickled over a pipe) while the command writes its files, and exits at the end of its input
without the interpreter's teardown. A LeRobot episode's command starts one at once, which forks a twin once warm
(:data:`EPISODE_RENDERERS`). Without
renderers (a library call, most tests) a figure is drawn here when it is made; a renderer that fails
or dies has its figures drawn here too, so a report never loses one.
"""

from __future__ import annotations

import base64
import contextlib
import html
import io
import os
import pickle
import queue
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Literal

if TYPE_CHECKING:
    from framechain.analysis.lab import TiltRow

#: zlib level of the report's PNGs (crops and plots): the same pixels as the default 6, smaller for
#: plots, in less than half the time.
PNG_COMPRESS_LEVEL = 3
#: Fixed margins (inches): tick labels of up to 6 characters and the axis label on the left, the last
#: x tick label's overhang on the right, x tick labels and label below, and above a title (or none).
LEFT_IN, RIGHT_IN, BOTTOM_IN = 0.85, 0.3, 0.6
Top = Literal["none", "title", "suptitle"]
TOP_IN: dict[Top, float] = {"none": 0.2, "title": 0.4, "suptitle": 0.5}
#: Space between the columns of a figure (inches): the right axes' tick labels and its axis label.
BETWEEN_IN = 0.85
#: Pixels a text may stick out before the figure is laid out again (antialiasing, rounding).
SLACK_PX = 1.0


class Figure:
    """A figure of the report: its file name, caption and PNG (drawn here, or by the renderer process
    and waited for when first read)."""

    def __init__(self, name: str, caption: str, png: bytes | Callable[[], bytes]) -> None:
        self.name = name
        self.caption = caption
        self._png = png

    @property
    def png(self) -> bytes:
        if callable(self._png):
            self._png = self._png()
        return self._png


#: One recorded call: (target, method, args, kwargs); target -1 is the figure, i its i-th axes.
Call = tuple[int, str, tuple[Any, ...], dict[str, Any]]


@dataclass
class Sketch:
    """A figure described but not drawn: its size and layout, and the matplotlib calls made on it and on
    its axes, in order. Plain data (pickled to the renderer process); :func:`draw` makes the figure."""

    width_in: float
    height_in: float
    columns: int
    top: Top
    dpi: int
    calls: list[Call] = field(default_factory=list)


class _Recorder:
    """Stands for the figure (target -1) or one of its axes: every method called on it is recorded."""

    def __init__(self, sketch: Sketch, target: int) -> None:
        self.sketch = sketch
        self._target = target

    def __getattr__(self, method: str) -> Callable[..., None]:
        if method.startswith("_"):  # copy and pickle probe for special methods: not figure calls
            raise AttributeError(method)

        def record(*args: Any, **kwargs: Any) -> None:
            self.sketch.calls.append((self._target, method, args, kwargs))

        return record


def new_figure(width_in: float, height_in: float, *, columns: int = 1, top: Top = "none",
               dpi: int = 100) -> tuple[Any, list[Any]]:
    """A figure of ``columns`` axes side by side, its margins fixed (``top``: "none", "title" above each
    axes or a "suptitle"), as stand-ins that record the matplotlib calls made on them (their return
    values are not available): the figure is drawn where matplotlib is loaded, by :func:`figure_png`."""
    sketch = Sketch(width_in, height_in, columns, top, dpi)
    return _Recorder(sketch, -1), [_Recorder(sketch, i) for i in range(columns)]


def draw(sketch: Sketch) -> Any:
    """The matplotlib figure of a sketch, its recorded calls made. No pyplot: nothing global to close."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure as MplFigure

    width_in, height_in, columns = sketch.width_in, sketch.height_in, sketch.columns
    fig = MplFigure(figsize=(width_in, height_in), dpi=sketch.dpi)
    FigureCanvasAgg(fig)  # the figure's canvas: drawn by savefig, its renderer read after
    axes = fig.subplots(1, columns, squeeze=False)[0].tolist()
    column_in = (width_in - LEFT_IN - RIGHT_IN - BETWEEN_IN * (columns - 1)) / columns
    fig.subplots_adjust(left=LEFT_IN / width_in, right=1.0 - RIGHT_IN / width_in, bottom=BOTTOM_IN / height_in,
                        top=1.0 - TOP_IN[sketch.top] / height_in, wspace=BETWEEN_IN / column_in)
    for target, method, args, kwargs in sketch.calls:
        getattr(fig if target < 0 else axes[target], method)(*args, **kwargs)
    return fig


def figure_png(fig: Any, name: str, caption: str) -> Figure:
    """The figure ``new_figure`` gave, drawn and encoded as PNG: by the renderer process where one runs
    (:func:`renderers`; the PNG is waited for when first read), else here."""
    return Figure(name, caption, submit(fig.sketch))


def render_png(sketch: Sketch) -> bytes:
    """Draw a sketch and encode it as PNG; laid out tightly and drawn again only when a text was cut off."""
    fig = draw(sketch)
    png = _png(fig)
    if _text_cut_off(fig):
        fig.tight_layout()
        # tight_layout leaves a placeholder layout engine, for which savefig lays out in one more (blind)
        # draw before the real one; the layout is done, so none is needed.
        fig.set_layout_engine(None)
        png = _png(fig)
    return png


def _png(fig: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    return buf.getvalue()


def _text_cut_off(fig: Any) -> bool:
    """After a draw: does a title, axis label, offset or tick label in view leave the figure, or a label
    of one axes reach into another?"""
    renderer = fig.canvas.get_renderer()
    width, height = fig.bbox.width, fig.bbox.height
    for ax in fig.axes:
        others = [o.get_window_extent(renderer) for o in fig.axes if o is not ax]
        for text in _texts(ax):
            if not text.get_visible() or not text.get_text():
                continue
            box = text.get_window_extent(renderer)
            if box.x0 < -SLACK_PX or box.y0 < -SLACK_PX or box.x1 > width + SLACK_PX or box.y1 > height + SLACK_PX:
                return True
            if any(box.overlaps(other) for other in others):
                return True
    title = getattr(fig, "_suptitle", None)  # the Text (get_suptitle gives only its string)
    if title is not None and title.get_text():
        box = title.get_window_extent(renderer)
        return bool(box.x0 < -SLACK_PX or box.x1 > width + SLACK_PX or box.y1 > height + SLACK_PX)
    return False


def _texts(ax: Any) -> list[Any]:
    """An axes' titles and axis labels, and the labels of the ticks drawn (those inside the view)."""
    out = [ax.title, ax.xaxis.label, ax.yaxis.label, ax.xaxis.offsetText, ax.yaxis.offsetText]
    for axis in (ax.xaxis, ax.yaxis):
        lo, hi = sorted(axis.get_view_interval())
        span = hi - lo
        out += [t.label1 for t in axis.majorTicks if lo - 1e-9 * span <= t.get_loc() <= hi + 1e-9 * span]
    return out


def figure_html(fig: Figure) -> str:
    """The figure embedded in HTML (base64 PNG) with its caption."""
    e = html.escape
    data = base64.b64encode(fig.png).decode("ascii")
    return (f"<figure><img alt='{e(fig.caption)}' src='data:image/png;base64,{data}'>"
            f"<figcaption>{e(fig.caption)}</figcaption></figure>")


# -- renderer processes ---------------------------------------------------------------------------
#: Renderer processes a report command starts (two cores: the command's and one drawing beside it,
#: the other drawing while the command waits for the last figures); FRAMECHAIN_RENDERERS sets it, 0
#: draws in the command's own process.
RENDERERS = 2
#: Renderers for a LeRobot episode's report: one process and a twin it forks once matplotlib is loaded
#: (:func:`renderers`' ``twins``). Its figures are two per camera, each drawn in about 0.05 s, once the cameras are
#: measured; a renderer takes about 0.45 s of a core to start and load matplotlib, and the cameras' measurement wants
#: both cores (a generated two-camera episode: 5% less wall time and 11% less CPU with one process than with two, over
#: 8 alternations), while a twin costs a fork and draws half the figures (the same episode: 1.87 s against 1.96 s with
#: one renderer, median of 12 alternations; the 10-minute benchmark log's 13 figures, drawn while its analysis takes
#: one core, are 4% faster with two processes).
EPISODE_RENDERERS = 2
RENDERERS_VARIABLE = "FRAMECHAIN_RENDERERS"
#: How much lower a renderer's priority is than the command's (it only takes the time a core is idle).
NICE = 10


class RenderError(RuntimeError):
    """A renderer could not draw a figure (it failed or died): the figure is drawn here instead."""


class _Pool:
    """Renderer processes fed from one queue, one thread per channel writing a sketch and reading its PNG: a process's
    stdin and stdout, and with ``twins`` the pipes of the twin it forks (:func:`serve_renderer`)."""

    def __init__(self, workers: int, *, twins: bool = False) -> None:
        self._jobs: queue.Queue[tuple[Sketch, Future[bytes]] | None] = queue.Queue()
        self._workers = workers
        self._twins = twins
        self._processes: list[subprocess.Popen[bytes]] = []
        self._channels: list[tuple[IO[bytes], IO[bytes]]] = []
        self._threads: list[threading.Thread] = []

    @property
    def started(self) -> bool:
        return bool(self._processes)

    def start(self) -> None:
        """Start the processes (once; a sketch submitted before starts them)."""
        if self._processes:
            return
        processes = 1 if self._twins else self._workers
        for number in range(processes):
            twins = [(os.pipe(), os.pipe()) for _ in range(self._workers - 1 if self._twins and number == 0 else 0)]
            ends = [str(fd) for sketches, replies in twins for fd in (sketches[0], replies[1])]
            process = subprocess.Popen([sys.executable, "-c", _RENDERER_MAIN, *ends], stdin=subprocess.PIPE,
                                       stdout=subprocess.PIPE, pass_fds=[int(fd) for fd in ends])
            assert process.stdin is not None
            assert process.stdout is not None
            self._processes.append(process)
            self._channels.append((process.stdin, process.stdout))
            for (sketch_read, sketch_write), (reply_read, reply_write) in twins:
                os.close(sketch_read)  # the renderer's ends, open in it now
                os.close(reply_write)
                self._channels.append((os.fdopen(sketch_write, "wb"), os.fdopen(reply_read, "rb")))
        self._threads = [threading.Thread(target=self._serve, args=channel, daemon=True, name="framechain-renderer")
                         for channel in self._channels]
        for thread in self._threads:
            thread.start()

    def submit(self, sketch: Sketch) -> Future[bytes]:
        self.start()
        future: Future[bytes] = Future()
        self._jobs.put((sketch, future))
        return future

    def _serve(self, sketches: IO[bytes], replies: IO[bytes]) -> None:
        while (job := self._jobs.get()) is not None:
            sketch, future = job
            try:
                pickle.dump(sketch, sketches, protocol=pickle.HIGHEST_PROTOCOL)
                sketches.flush()
                drawn, value = pickle.load(replies)
            except (OSError, ValueError, EOFError, pickle.PickleError) as err:  # ValueError: closed by close(kill)
                future.set_exception(RenderError(f"the renderer process ended ({type(err).__name__})"))
                continue
            if drawn:
                future.set_result(value)
            else:
                future.set_exception(RenderError(value))

    def close(self, *, kill: bool) -> None:
        """Stop the renderers: at once (``kill``, the command failed), else once their queue is done."""
        for _ in self._threads:
            self._jobs.put(None)
        if kill:
            for process in self._processes:
                process.kill()
        for sketches, _replies in self._channels:
            with contextlib.suppress(OSError):
                sketches.close()  # end of input: a renderer (or twin) exits
        for thread in self._threads:
            thread.join()
        for process in self._processes:
            process.wait()
        for _sketches, replies in self._channels:
            replies.close()


#: The renderers of the running command (none, or one pool).
_running: list[_Pool] = []


@contextlib.contextmanager
def renderers(workers: int | None = None, *, start_now: bool = True, usual: int = RENDERERS, twins: bool = False
              ) -> Iterator[None]:
    """Within this block, figures are drawn by ``workers`` renderers (None: the FRAMECHAIN_RENDERERS variable, else
    ``usual``), started now or, with ``start_now`` False, by :func:`start_renderers` (or the first figure, whichever
    comes first): as many processes, or with ``twins`` one process and the twins it forks once it has loaded
    matplotlib (no second load; a twin is ready only after it)."""
    if workers is None:
        workers = _renderers_wanted(usual)
    if _running or workers < 1:
        yield
        return
    pool = _Pool(workers, twins=twins)
    if start_now:
        pool.start()
    _running.append(pool)
    failed = True
    try:
        yield
        failed = False
    finally:
        _running.clear()
        pool.close(kill=failed)


def start_renderers() -> None:
    """Start the renderers of the running :func:`renderers` block, if not yet started (else nothing).

    A command that reads a log starts them once the read is done: the read keeps both cores busy
    (its decompressing thread beside it), the analysis after it only one, and a renderer needs about
    0.6 s of a core to load matplotlib before its first figure.
    """
    if _running:
        _running[0].start()


def _renderers_wanted(usual: int) -> int:
    text = os.environ.get(RENDERERS_VARIABLE, str(usual))
    if not text.strip().isdigit():
        from framechain.errors import FramechainError

        raise FramechainError(f"{RENDERERS_VARIABLE}={text!r}: expected a whole number of renderer processes (0: none)")
    return int(text)


def submit(sketch: Sketch) -> bytes | Callable[[], bytes]:
    """The PNG of a sketch: drawn here at once without renderers, else a callable that waits for it."""
    if not _running:
        return render_png(sketch)
    future = _running[0].submit(sketch)

    def result() -> bytes:
        try:
            return future.result()
        except RenderError:
            return render_png(sketch)

    return result


def _warm_up() -> None:
    """matplotlib and its fonts loaded, before the first sketch comes."""
    with contextlib.suppress(Exception):
        render_png(Sketch(6.4, 3.6, 1, "none", 20, [(0, "set_xlabel", ("loads the fonts",), {})]))


def _serve_stdio(source: IO[bytes], sink: IO[bytes]) -> None:
    """A renderer: sketches in from ``source``, (drawn, PNG or the error) out to ``sink``, until end of input."""
    while True:
        try:
            sketch: Any = pickle.load(source)
        except EOFError:
            return
        try:
            reply: tuple[bool, Any] = (True, render_png(sketch))
        except Exception as err:  # the command draws this one itself
            reply = (False, f"{type(err).__name__}: {err}")
        pickle.dump(reply, sink, protocol=pickle.HIGHEST_PROTOCOL)
        sink.flush()


#: A renderer process's program (``-c``: the module imported once, not run again as ``__main__``). An
#: interpreter that cannot import framechain (a frozen or zipped command) exits quietly: the command
#: draws the figures itself.
_RENDERER_MAIN = ("try:\n    from framechain.sinks.plots import serve_renderer\n"
                  "except ImportError:\n    raise SystemExit(1)\nserve_renderer()")


def serve_renderer() -> None:
    """A renderer process (:func:`renderers` starts them): low priority, sketches in on stdin, PNGs out; its arguments,
    pairs of file descriptors (sketches in, PNGs out), are the channels of the twins it forks once warm."""
    import signal

    if hasattr(os, "nice"):
        os.nice(NICE)
    # Ctrl-C reaches the whole process group: the command stops its renderers itself, without their tracebacks.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # The PNGs go out on a copy of stdout; stdout itself becomes stderr, so that a stray print (a
    # library's warning) cannot corrupt the replies.
    replies = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    _warm_up()
    ends = [int(fd) for fd in sys.argv[1:]]
    twins = list(zip(ends[::2], ends[1::2], strict=True))
    source, sink = sys.stdin.buffer, replies
    for number, (sketch_fd, reply_fd) in enumerate(twins):
        try:
            child = os.fork()
        except OSError:  # no twin: the command draws what it sends this channel
            child = -1
        if child == 0:  # the twin: its own channel only
            source.close()
            sink.close()
            # stdin is the renderer's channel: held open here, the command's writes to a renderer that died would
            # fill the pipe and wait, not fail.
            null = os.open(os.devnull, os.O_RDONLY)
            os.dup2(null, 0)
            os.close(null)
            for other in twins[number + 1:]:
                for fd in other:
                    os.close(fd)
            source, sink = os.fdopen(sketch_fd, "rb"), os.fdopen(reply_fd, "wb")
            break
        os.close(sketch_fd)
        os.close(reply_fd)
    with contextlib.suppress(OSError):  # the command gone (it failed and stopped reading): end quietly
        _serve_stdio(source, sink)
    # Every reply is flushed as it is made: nothing is left to save. The interpreter's teardown (matplotlib's
    # modules and font caches, about 0.25 s) would only make the command, which waits for its renderers to
    # end, wait longer.
    sys.stdout.flush()  # (a stray print, on stderr)
    sys.stderr.flush()
    os._exit(0)


def plot_tilt(rows: Sequence[TiltRow], path: str | Path, *, tolerance_m: float = 0.01) -> None:
    """Error against pitch, one line per depth, with the gripper tolerance."""
    fig, (ax,) = new_figure(6.0, 4.0, dpi=110)
    for depth in sorted({r.depth_m for r in rows}):
        sel = sorted((r for r in rows if r.depth_m == depth), key=lambda r: r.pitch_deg)
        ax.plot([r.pitch_deg for r in sel], [r.error_m * 1e3 for r in sel], label=f"Z = {depth:g} m")
    ax.axhline(tolerance_m * 1e3, color="k", ls="--", lw=1, label=f"tolerance {tolerance_m * 1e3:g} mm")
    ax.set_xlabel("camera pitch lost from the extrinsic (deg)")
    ax.set_ylabel("world-frame error (mm)")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.grid(True, alpha=0.3)
    ax.legend()
    drawn = draw(fig.sketch)
    drawn.tight_layout()  # any format the path names (png, svg, pdf): laid out once, not on a hot path
    drawn.savefig(path)
