"""Matplotlib figures (Agg, files only): one way to make a figure, lay it out and encode it as PNG.

A figure is laid out by fixed margins in inches, wide enough for the report's axis labels, and drawn
once. ``tight_layout`` would fit each figure's margins exactly, but it draws every tick label once
more to measure it: 40% of a figure's cost (a second of a report's). After the one draw,
:func:`figure_png` checks that no title, axis label or tick label fell outside the figure or onto
another axes, and only then lays the figure out tightly and draws it again.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

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


@dataclass(frozen=True)
class Figure:
    name: str
    caption: str
    png: bytes


def new_figure(width_in: float, height_in: float, *, columns: int = 1, top: Top = "none",
               dpi: int = 100) -> tuple[Any, list[Any]]:
    """A figure of ``columns`` axes side by side, its margins fixed (``top``: "none", "title" above each
    axes or a "suptitle"). No pyplot: nothing global to close."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure as MplFigure

    fig = MplFigure(figsize=(width_in, height_in), dpi=dpi)
    FigureCanvasAgg(fig)  # the figure's canvas: drawn by savefig, its renderer read after
    axes = fig.subplots(1, columns, squeeze=False)[0].tolist()
    column_in = (width_in - LEFT_IN - RIGHT_IN - BETWEEN_IN * (columns - 1)) / columns
    fig.subplots_adjust(left=LEFT_IN / width_in, right=1.0 - RIGHT_IN / width_in, bottom=BOTTOM_IN / height_in,
                        top=1.0 - TOP_IN[top] / height_in, wspace=BETWEEN_IN / column_in)
    return fig, axes


def figure_png(fig: Any, name: str, caption: str) -> Figure:
    """Draw and encode a figure as PNG; laid out tightly and drawn again only when a text was cut off."""
    png = _png(fig)
    if _text_cut_off(fig):
        fig.tight_layout()
        # tight_layout leaves a placeholder layout engine, for which savefig lays out in one more (blind)
        # draw before the real one; the layout is done, so none is needed.
        fig.set_layout_engine(None)
        png = _png(fig)
    return Figure(name=name, caption=caption, png=png)


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
    fig.tight_layout()  # any format the path names (png, svg, pdf): laid out once, not on a hot path
    fig.savefig(path)
