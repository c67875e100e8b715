"""The default layout of a Rerun recording, made of the views that have data: the world in 3D beside the cameras'
views, series and text below."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from framechain.config.chain import ChainFrames
from framechain.sinks.overlay import (
    ImageOverlay,
)
from framechain.sinks.rerun_common import IMAGE_PLANE_SUFFIX, LOG_TIME, OBS_INDEX, SENSOR_TIME, rerun_pixels
from framechain.sinks.rerun_egomotion import RATE_ENTITY

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


Bounds = tuple[float, float, float, float]


def has_data(logged: Mapping[str, int], *roots: str) -> bool:
    """Whether a row was logged at one of ``roots`` or below it (``logged``: rows per entity path)."""
    return any(rows > 0 and any(entity == r or entity.startswith(r + "/") for r in roots)
               for entity, rows in logged.items())


def default_blueprint(frames: ChainFrames, logged: Mapping[str, int], *,
                      cameras: Sequence[tuple[str, str, Bounds | None]], collapse_panels: bool = False,
                      curves: Sequence[tuple[str, str]] = (), curves_first: bool = False, window_s: float | None = None,
                      timelines: Sequence[str] = (SENSOR_TIME, LOG_TIME, OBS_INDEX)) -> rrb.Blueprint:
    """The views that have data in this recording (``logged``: rows per entity path, as the sinks return them),
    whatever the kind of run: the world in 3D (and all observations' world points) beside the cameras' views
    (``cameras``: frame, entity root, image bounds; a camera with its images, depth or detections); below them
    the cameras' rotation rates (one plot each: measured, as declared, as fitted), the error series with the
    error-against-size bar charts (``curves``: entity, title; ``curves_first``: that tab first), the error in
    the image, the time gaps or a rig's distances between cameras' sightings, and the text. ``window_s``: the
    series show that many seconds either side of the time cursor (a log of one moment); ``timelines``: the
    recording's, the time panel's first. ``collapse_panels`` hides the viewer's side panels (screenshots)."""
    import rerun.blueprint as rrb

    axis = None if window_s is None else rrb.TimeAxis(view_range=rrb.TimeRange(
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-window_s),
        end=rrb.TimeRangeBoundary.cursor_relative(seconds=window_s)))
    top = [group for group in (_world_views(frames, logged, cameras, timelines), _camera_views(logged, cameras))
           if group is not None]
    bottom = [group for group in (_rate_views(logged, axis), _error_views(logged, curves, curves_first, axis),
                                  _image_and_time_views(logged, axis), _text_views(logged)) if group is not None]
    rows = [rrb.Horizontal(*top, column_shares=[1] * len(top)) if len(top) > 1 else top[0]]
    if bottom:
        rows.append(rrb.Horizontal(*bottom, column_shares=[1] * len(bottom)) if len(bottom) > 1 else bottom[0])
    return rrb.Blueprint(
        rrb.Vertical(*rows, row_shares=[3, 2][: len(rows)]),
        rrb.TimePanel(state="collapsed" if collapse_panels else "expanded", timeline=timelines[0]),
        collapse_panels=collapse_panels,
    )


def _one_or_tabs(views: Sequence[rrb.View | rrb.Container], active_tab: int = 0) -> rrb.View | rrb.Container | None:
    import rerun.blueprint as rrb

    if not views:
        return None
    return views[0] if len(views) == 1 else rrb.Tabs(*views, active_tab=active_tab)


def _world_views(frames: ChainFrames, logged: Mapping[str, int], cameras: Sequence[tuple[str, str, Bounds | None]],
                 timelines: Sequence[str]) -> rrb.View | rrb.Container | None:
    """The world in 3D at the cursor, and every observation's world point at once (where there are any)."""
    import rerun.blueprint as rrb

    roots = [root for _frame, root, _bounds in cameras]
    # With colour images, the depth cloud would bury the points: it stays in the depth view.
    buried = [f"- {r}/depth" for r in roots if has_data(logged, f"{r}/image", f"{r}/video")]
    world = rrb.Spatial3DView(
        name=f"World ({frames.world})", origin="/",
        contents=["+ /**", "- /series/**", "- /log/**", "- /summary", "- /checks", "- /curves/**",
                  *(f"- {r}/overlay/**" for r in roots), *buried],
        spatial_information=rrb.SpatialInformation(target_frame=frames.world),
    )
    points = ["/points/recomputed/world", "/points/as_run/world", "/points/as_run/target", "/points/rig",
              "/points/reference"]
    if not has_data(logged, *points):
        return world if has_data(logged, "/tf", "/frames", "/points") else None
    history = rrb.Spatial3DView(
        name="All observations (world points)", origin="/",
        contents=[*(f"+ {p}/**" for p in points), *(f"+ {p}" for p in points), "+ /points/error/world",
                  "+ /frames/**", "+ /tf/**"],
        spatial_information=rrb.SpatialInformation(target_frame=frames.world),
        time_ranges=[rrb.VisibleTimeRange(name, start=rrb.TimeRangeBoundary.infinite(),
                                          end=rrb.TimeRangeBoundary.infinite()) for name in timelines],
    )
    return rrb.Tabs(world, history)


def _camera_views(logged: Mapping[str, int], cameras: Sequence[tuple[str, str, Bounds | None]]
                  ) -> rrb.View | rrb.Container | None:
    """Each camera that shows something (its images or video, its detections, its depth): its image plane with
    the chain drawn on it, and its depth frames beside (a tab) when it has images too."""
    import rerun.blueprint as rrb

    panels: list[rrb.View | rrb.Container] = []
    for frame, root, box in cameras:
        images = has_data(logged, f"{root}/image", f"{root}/video")
        depth = has_data(logged, f"{root}/depth")
        if not (images or depth or has_data(logged, f"{root}/detections", f"{root}/overlay")):
            continue
        plane = rrb.SpatialInformation(target_frame=frame + IMAGE_PLANE_SUFFIX)
        bounds = None if box is None else rrb.VisualBounds2D(x_range=box[:2], y_range=box[2:])
        view = rrb.Spatial2DView(name=f"Camera ({frame})", origin=root,
                                 contents=[f"+ {root}/**", f"- {root}/depth"] if images else [f"+ {root}/**"],
                                 spatial_information=plane, visual_bounds=bounds)
        if images and depth:
            panels.append(rrb.Tabs(view, rrb.Spatial2DView(
                name=f"Depth ({frame})", origin=root, contents=[f"+ {root}/depth", f"+ {root}/detections"],
                spatial_information=plane)))
        else:
            panels.append(view)
    if len(panels) > 1:
        return rrb.Grid(*panels)
    return panels[0] if panels else None


def _rate_views(logged: Mapping[str, int], axis: rrb.TimeAxis | None) -> rrb.View | rrb.Container | None:
    """One plot per camera measured by its own motion: its rotation rate from its images, and as forward kinematics
    predicts it through the declared and through the fitted link, mount and time."""
    import rerun.blueprint as rrb

    bases = sorted({e[: -len("/measured")] for e, n in logged.items()
                    if n > 0 and e.startswith(RATE_ENTITY + "/") and e.endswith("/measured") and e.count("/") == 4})
    plots = [rrb.TimeSeriesView(name=f"Rotation rate of {base.rsplit('/', 1)[-1]} (deg/s): measured, as declared, "
                                "as fitted", origin=base,
                                contents=["+ $origin/measured", "+ $origin/declared", "+ $origin/corrected"],
                                axis_x=axis) for base in bases]
    if len(plots) > 1:
        return rrb.Vertical(*plots)
    return plots[0] if plots else None


def _error_views(logged: Mapping[str, int], curves: Sequence[tuple[str, str]], curves_first: bool,
                 axis: rrb.TimeAxis | None) -> rrb.View | rrb.Container | None:
    """The error series (each hop's own, the world error the findings explain and what remains) and the
    error-against-size bar charts, as tabs."""
    import rerun.blueprint as rrb

    errors: list[rrb.View | rrb.Container] = []
    if has_data(logged, "/series/error_mm"):
        errors.append(rrb.TimeSeriesView(name="Error (mm): each hop's own, the world's", origin="/series/error_mm",
                                         axis_x=axis))
    # No legend: it names entity paths over the bars; the title says what each colour is.
    charts = [rrb.BarChartView(name=title, origin=entity, plot_legend=rrb.PlotLegend(visible=False))
              for entity, title in curves if has_data(logged, entity)]
    return _one_or_tabs([*errors, *charts], active_tab=len(errors) if curves_first and charts else 0)


def _image_and_time_views(logged: Mapping[str, int], axis: rrb.TimeAxis | None) -> rrb.View | rrb.Container | None:
    """The as-run point's distance from the recomputed one in the image, the per-hop time gaps, a rig's distances
    between cameras' sightings."""
    import rerun.blueprint as rrb

    views = [rrb.TimeSeriesView(name=name, origin=origin, axis_x=axis) for origin, name in (
        ("/series/error_px", "As-run vs recomputed in the image (px)"),
        ("/series/rig", "Distance to another camera's sighting (mm)"),
        ("/series/gap_ms", "Per-hop time gap (ms)")) if has_data(logged, origin)]
    return _one_or_tabs(views)


def _text_views(logged: Mapping[str, int]) -> rrb.View | rrb.Container | None:
    """The summary (verdict, counts, findings, colours), the findings and rejections, and what the log can show.

    The summary first: the log view sizes its columns to what it shows first, and cut findings to a few letters.
    """
    import rerun.blueprint as rrb

    views: list[rrb.View | rrb.Container] = []
    if has_data(logged, "/summary"):
        views.append(rrb.TextDocumentView(name="Summary", origin="/summary"))
    if has_data(logged, "/log"):
        views.append(rrb.TextLogView(name="Findings and rejections", origin="/log", columns=rrb.TextLogColumns(
            timeline_columns=[], text_log_columns=["loglevel", "body"])))
    if has_data(logged, "/checks"):
        views.append(rrb.TextDocumentView(name="What this log can show", origin="/checks"))
    return _one_or_tabs(views)
