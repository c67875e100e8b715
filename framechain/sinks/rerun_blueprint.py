"""The default layout of a Rerun recording: the world in 3D beside the camera's view, series and text below."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from framechain.config.chain import ChainFrames
from framechain.sinks.overlay import (
    ImageOverlay,
)
from framechain.sinks.rerun_common import IMAGE_PLANE_SUFFIX, LOG_TIME, OBS_INDEX, SENSOR_TIME, rerun_pixels

if TYPE_CHECKING:
    import rerun.blueprint as rrb


def image_view_bounds(overlay: ImageOverlay) -> tuple[float, float, float, float] | None:
    """(u_min, u_max, v_min, v_max) of the camera view in Rerun's image space, where the image spans (0, 0) ..
    (W, H): the image, widened to show most projected as-run points (the 90th percentile of how far they fall
    outside, at most one image size)."""
    have = overlay.width > 0
    if not have.any():
        return None
    w, h = float(overlay.width[have].max()), float(overlay.height[have].max())
    u0, u1, v0, v1 = 0.0, w, 0.0, h
    uv = rerun_pixels(overlay.as_run_uv[np.isfinite(overlay.as_run_uv).all(axis=1)])
    if uv.size:
        margin_u, margin_v = 0.04 * w, 0.04 * h
        u0 = max(min(u0, float(np.percentile(uv[:, 0], 10)) - margin_u), -w)
        u1 = min(max(u1, float(np.percentile(uv[:, 0], 90)) + margin_u), 2 * w)
        v0 = max(min(v0, float(np.percentile(uv[:, 1], 10)) - margin_v), -h)
        v1 = min(max(v1, float(np.percentile(uv[:, 1], 90)) + margin_v), 2 * h)
    return u0, u1, v0, v1


def default_blueprint(frames: ChainFrames, *, images: bool = False, collapse_panels: bool = False,
                      image_bounds: tuple[float, float, float, float] | None = None,
                      curves: Sequence[tuple[str, str]] = (), curves_first: bool = False,
                      camera_motion: bool = False,
                      cameras: Sequence[tuple[str, str, tuple[float, float, float, float] | None]] = (),
                      window_s: float | None = None) -> rrb.Blueprint:
    """The 3D view in the world frame (and all observations' world points) beside the camera's 2D view
    (its images with the chain drawn on them when ``images``, else the depth frames); below them the
    per-hop error, the error in the image and the time gaps as series, and the findings.
    ``collapse_panels`` hides the viewer's side panels (screenshots); ``image_bounds`` (u_min, u_max,
    v_min, v_max) frames the camera view (see :func:`image_view_bounds`). ``curves`` (entity, title): the
    error against each fault family's size, as bar charts beside the per-hop error (``curves_first``: shown
    first, where no hop error is logged); what the log can show and the labels are a tab beside the findings.
    ``camera_motion`` puts the cameras' rotation rate, from their images against forward kinematics, first
    beside the per-hop error. ``cameras`` (frame, entity root, image bounds) of a rig: one view per camera
    beside the 3D view instead of the one camera's, and the distances between cameras' sightings in place of
    the time gaps. ``window_s``: the series show that many seconds either side of the time cursor (a log of one
    moment, where the viewer would otherwise pick months); None: the whole log."""
    import rerun.blueprint as rrb

    axis = None if window_s is None else rrb.TimeAxis(view_range=rrb.TimeRange(
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-window_s),
        end=rrb.TimeRangeBoundary.cursor_relative(seconds=window_s)))
    # With colour images, the depth cloud would bury the points: it stays in the depth tab.
    roots = [root for _frame, root, _bounds in cameras] or ["/camera"]
    world = rrb.Spatial3DView(
        name=f"World ({frames.world})", origin="/",
        contents=["+ /**", "- /series/**", "- /log/**", "- /summary", *(f"- {r}/overlay/**" for r in roots),
                  *([f"- {r}/depth" for r in roots] if images else [])],
        spatial_information=rrb.SpatialInformation(target_frame=frames.world),
    )
    history = rrb.Spatial3DView(
        name="All observations (world points)", origin="/",
        contents=["+ /points/recomputed/world", "+ /points/as_run/world", "+ /points/as_run/target", "+ /points/rig/**",
                  "+ /points/reference/**", "+ /points/error/world", "+ /frames/**", "+ /tf/**"],
        spatial_information=rrb.SpatialInformation(target_frame=frames.world),
        time_ranges=[rrb.VisibleTimeRange(name, start=rrb.TimeRangeBoundary.infinite(),
                                          end=rrb.TimeRangeBoundary.infinite())
                     for name in (SENSOR_TIME, LOG_TIME, OBS_INDEX)],
    )
    plane = rrb.SpatialInformation(target_frame=frames.camera + IMAGE_PLANE_SUFFIX)
    bounds = None if image_bounds is None else rrb.VisualBounds2D(x_range=image_bounds[:2], y_range=image_bounds[2:])
    camera = rrb.Spatial2DView(
        name=f"Camera ({frames.camera})", origin="/camera",
        contents=["+ /camera/**", "- /camera/depth"] if images else ["+ /camera/**"],
        spatial_information=plane, visual_bounds=bounds,
    )
    views: rrb.Tabs | rrb.Spatial2DView | rrb.Grid = camera
    if images:
        depth = rrb.Spatial2DView(name=f"Depth ({frames.camera})", origin="/camera",
                                  contents=["+ /camera/depth", "+ /camera/detections"], spatial_information=plane)
        views = rrb.Tabs(camera, depth)
    if cameras:
        views = rrb.Grid(*(rrb.Spatial2DView(
            name=f"Camera ({frame})", origin=root, contents=[f"+ {root}/**", f"- {root}/depth"],
            spatial_information=rrb.SpatialInformation(target_frame=frame + IMAGE_PLANE_SUFFIX),
            visual_bounds=None if box is None else rrb.VisualBounds2D(x_range=box[:2], y_range=box[2:]))
            for frame, root, box in cameras))
        gaps: rrb.TimeSeriesView | None = rrb.TimeSeriesView(name="Distance to another camera's sighting (mm)",
                                                             origin="/series/rig", axis_x=axis)
    else:
        gaps = None
    errors = _error_views(curves, curves_first=curves_first, camera_motion=camera_motion, axis=axis)
    pixels = rrb.TimeSeriesView(name="As-run vs recomputed in the image (px)", origin="/series/error_px", axis_x=axis)
    gaps = gaps or rrb.TimeSeriesView(name="Per-hop time gap (ms)", origin="/series/gap_ms", axis_x=axis)
    text = _text_views()
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(rrb.Tabs(world, history), views, column_shares=[1, 1]),
            rrb.Horizontal(errors, rrb.Tabs(pixels, gaps) if images else gaps, text, column_shares=[2, 2, 2]),
            row_shares=[3, 2],
        ),
        rrb.TimePanel(state="collapsed" if collapse_panels else "expanded", timeline=SENSOR_TIME),
        collapse_panels=collapse_panels,
    )


def _text_views() -> rrb.Tabs:
    """The summary (verdict, counts, findings, colours), the findings and rejections, and what the log can show.

    The summary first: the log view sizes its columns to what it shows first, and cut findings to a few letters.
    """
    import rerun.blueprint as rrb

    findings = rrb.TextLogView(name="Findings and rejections", origin="/log", columns=rrb.TextLogColumns(
        timeline_columns=[], text_log_columns=["loglevel", "body"]))
    return rrb.Tabs(rrb.TextDocumentView(name="Summary", origin="/summary"), findings,
                    rrb.TextDocumentView(name="What this log can show", origin="/checks"))


def _error_views(curves: Sequence[tuple[str, str]], *, curves_first: bool, camera_motion: bool,
                 axis: rrb.TimeAxis | None = None) -> rrb.TimeSeriesView | rrb.Tabs:
    """The error series (each hop's own, the world error the findings explain and what remains), with the
    error-against-size bar charts and the cameras' rotation rate as tabs."""
    import rerun.blueprint as rrb

    errors: rrb.TimeSeriesView | rrb.Tabs = rrb.TimeSeriesView(name="Error (mm): each hop's own, the world's",
                                                               origin="/series/error_mm", axis_x=axis)
    if curves:
        # No legend: it names entity paths over the bars; the title says what each colour is.
        charts = [rrb.BarChartView(name=title, origin=entity, plot_legend=rrb.PlotLegend(visible=False))
                  for entity, title in curves]
        errors = rrb.Tabs(errors, *charts, active_tab=1 if curves_first else 0)
    if camera_motion:
        rates = rrb.TimeSeriesView(name="Camera rotation rate: images vs forward kinematics (deg/s)",
                                   origin="/series/rotation_rate_deg_s", axis_x=axis)
        errors = rrb.Tabs(rates, errors)
    return errors
