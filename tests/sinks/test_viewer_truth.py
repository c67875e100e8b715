"""What the Rerun viewer shows is what is true: pixels in Rerun's convention, the view of the whole image, the
detector's own tag centre beside framechain's, one name per frame, the error the findings explain as a series, a sane
time axis for a log of one moment, and one colour legend."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from rerun.chunk import RrdReader

from framechain.catalogue import Fault
from framechain.sinks.colors import (
    AS_RUN_COLOR,
    CORRECTED_COLOR,
    DETECTION_COLOR,
    ERROR_COLOR,
    FAULT_COLORS,
    HOP_COLORS,
    LEGEND,
    RECOMPUTED_COLOR,
    RECORDED_ERROR_COLOR,
    REFERENCE_COLOR,
    STALE_COLOR,
    USED_PIXEL_COLOR,
    legend_text,
)
from framechain.sinks.overlay import ImageOverlay
from framechain.sinks.rerun import RerunTarget, stream_replay
from framechain.sinks.rerun_blueprint import image_view_bounds
from tests.helpers.rerun_scene import T0, mast_camera_timeline, replayed_run
from tests.helpers.rrd_views import column_values, read_chunks


def _rgba(rgb: tuple[int, int, int]) -> int:
    r, g, b = rgb
    return (r << 24) | (g << 16) | (b << 8) | 0xFF


def _overlay(as_run_uv: list[float]) -> ImageOverlay:
    """One observation in a 160 x 120 image, its as-run point at ``as_run_uv`` (OpenCV pixels)."""
    nan2 = np.full((1, 2), np.nan)
    return ImageOverlay(detection_uv=nan2, corners_px=np.full((1, 4, 2), np.nan), detector_uv=nan2,
                        estimated=np.zeros(1, dtype=bool), recomputed_uv=nan2, as_run_uv=np.array([as_run_uv]),
                        as_run_role="world", image_row=np.zeros(1, dtype=np.int64), width=np.array([160]),
                        height=np.array([120]), finding=None, color=ERROR_COLOR)


def test_camera_view_spans_the_whole_image_in_rerun_space() -> None:
    # Rerun's image space: pixel column 159 spans 159 .. 160, so the image is 0 .. 160 (it was -0.5 .. 159.5,
    # which cut the last half column)
    assert image_view_bounds(_overlay([np.nan, np.nan])) == (0.0, 160.0, 0.0, 120.0)
    # an as-run point 40.5 px left of the image's first pixel centre (OpenCV u = -40.5) is at -40 in Rerun's space;
    # the view reaches 4% of the width (6.4 px) beyond it
    u0, u1, v0, v1 = image_view_bounds(_overlay([-40.5, 60.0])) or (0.0, 0.0, 0.0, 0.0)
    assert (u1, v0, v1) == (160.0, 0.0, 120.0)
    assert u0 == pytest.approx(-46.4)


@pytest.fixture(scope="module")
def fiducial_scene(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[tuple[bool, Any]]]:
    """The test_rerun scene, its first two detections tags: corners around the pixel used, and the centre their
    detector logged 0.7 px right and 0.4 px up of it (as TagSLAM's detector differs from the PnP centre)."""
    timeline = mast_camera_timeline()
    obs = timeline.observations
    quads = [[[u - 10, v - 10], [u + 10, v - 10], [u + 10, v + 10], [u - 10, v + 10]]
             for u, v in zip(obs.u[:2], obs.v[:2], strict=True)]
    side = {"obs_id": obs.obs_id[:2].tolist(), "corners_px": [np.ravel(q).tolist() for q in quads],
            "detector_centre_px": [[float(u) + 0.7, float(v) - 0.4] for u, v in zip(obs.u[:2], obs.v[:2], strict=True)]}
    timeline = timeline.replace(metadata={**timeline.metadata, "fiducials": {"corners": side}})
    rrd = tmp_path_factory.mktemp("fiducial") / "scene.rrd"
    stream_replay(replayed_run(timeline), RerunTarget.save(rrd))
    return read_chunks(rrd)


def test_the_detectors_centre_is_drawn_beside_the_pixel_framechain_used(
        fiducial_scene: dict[str, list[tuple[bool, Any]]]) -> None:
    centres = list(column_values(fiducial_scene, "/camera/overlay/detector_centre", "Points2D:positions"))
    # obs 100 used (80, 60), obs 101 (95, 50): the detector said (80.7, 59.6) and (95.7, 49.6), +0.5 in Rerun
    np.testing.assert_allclose([p for row in centres for p in row], [[81.2, 60.1], [96.2, 50.1]], atol=1e-5)
    labels = [label for r in column_values(fiducial_scene, "/camera/overlay/detector_centre", "Points2D:labels")
              for label in r]
    assert labels == ["obs 100: the detector's logged centre", "obs 101: the detector's logged centre"]
    colors = [c for r in column_values(fiducial_scene, "/camera/detections", "Points2D:colors") for c in r]
    # the two tags' pixels are framechain's estimate (light green); the plain detections the detector's own (green)
    assert colors[:2] == [_rgba(USED_PIXEL_COLOR)] * 2
    assert colors[2] == _rgba(DETECTION_COLOR)
    detections = [p for r in column_values(fiducial_scene, "/camera/detections", "Points2D:positions") for p in r]
    np.testing.assert_allclose(detections[:2], [[80.5, 60.5], [95.5, 50.5]])


def test_replay_frames_are_named_only_where_the_log_lacks_the_frame(
        fiducial_scene: dict[str, list[tuple[bool, Any]]]) -> None:
    # base_link and camera_optical_frame are in the log's tree: their @replay copies sit on them, unnamed
    for frame in ("base_link", "camera_optical_frame"):
        assert column_values(fiducial_scene, f"/frames/{frame}", "Points3D:labels") == [[frame]]
        assert column_values(fiducial_scene, f"/frames/replay/{frame}", "Points3D:labels") == []
        assert column_values(fiducial_scene, f"/frames/replay/{frame}", "TransformAxes3D:show_frame") == [[False]]


def test_static_spread_error_and_what_remains_are_series(tmp_path: Path) -> None:
    """With static-target evidence there are no as-run points: the error plot shows the world error the findings
    explain (each observation against its object's own position) and what remains once they are corrected."""
    made = replayed_run(mast_camera_timeline(), findings=[])
    obs = made.replay.observations
    used = obs.obs_id[[0, 2, 3]]  # the attribution used three observations
    before, after = np.array([0.004, 0.006, 0.002]), np.array([0.001, 0.002, 0.0005])
    attribution = replace(made.attribution, metric="static_spread",  # type: ignore[arg-type]
                          inputs=SimpleNamespace(obs_id=used), error_before=before, error_after=after,
                          findings=made.attribution.findings if made.attribution else ())
    rrd = tmp_path / "static.rrd"
    stream_replay(replace(made, attribution=attribution), RerunTarget.save(rrd))
    chunks = read_chunks(rrd)
    world = np.array([v[0] for v in column_values(chunks, "/series/error_mm/world_error", "Scalars:scalars")])
    np.testing.assert_allclose(world, [4.0, 6.0, 2.0])
    index = np.concatenate([b.column("obs_index").to_numpy() for s, b in chunks["/series/error_mm/world_error"]
                            if not s])
    assert index.tolist() == [0, 2, 3]
    names = column_values(chunks, "/series/error_mm/world_error", "SeriesLines:names")
    assert names == [["world error against the static target's own position (mm)"]]
    assert "/series/error_mm/corrected" not in chunks  # no finding: nothing corrected to show
    verdict = [t[0] for t in column_values(chunks, "/log/verdict", "TextLog:text")]
    assert verdict == [attribution.verdict]


def test_a_log_of_one_moment_has_a_time_axis_of_seconds(tmp_path: Path) -> None:
    """One image (all observations at one stamp): the series show 1 s either side of it, not months; and the
    findings panel says why nothing was found."""
    timeline = mast_camera_timeline()
    obs = timeline.observations
    one = replace(obs, stamp_ns=np.full(len(obs), T0 + 500 * 1_000_000),
                  log_time_ns=np.full(len(obs), T0 + 540 * 1_000_000))
    made = replayed_run(timeline.replace(observations=one))
    rrd = tmp_path / "moment.rrd"
    stream_replay(made, RerunTarget.save(rrd))
    reader = RrdReader(rrd)
    ranges: dict[str, list[Any]] = defaultdict(list)
    for chunk in reader.stream(store=reader.blueprints()[0]):
        batch = chunk.to_record_batch()
        if "TimeAxis:view_range" in batch.schema.names:
            ranges[chunk.entity_path].extend(batch.column("TimeAxis:view_range").to_pylist())
    # the time-gap series alone: no as-run points (no error series), no images (no pixel series)
    assert not any(entity.startswith(("/series/error_mm", "/series/error_px")) for entity in read_chunks(rrd))
    assert len(ranges) == 1
    for values in ranges.values():
        assert values[-1] == [{"start": -1_000_000_000, "end": 1_000_000_000}]  # ns either side of the cursor
    verdict = [t[0] for t in column_values(read_chunks(rrd), "/log/verdict", "TextLog:text")]
    assert len(verdict) == 1
    assert verdict[0].startswith("No attribution")
    # a log that spans 2 s keeps its whole time axis
    whole = tmp_path / "whole.rrd"
    stream_replay(replayed_run(timeline), RerunTarget.save(whole))
    reader = RrdReader(whole)
    assert not any("TimeAxis:view_range" in chunk.to_record_batch().schema.names
                   for chunk in reader.stream(store=reader.blueprints()[0]))


def test_one_legend_no_colour_means_two_things() -> None:
    legend = [rgb for rgb, _name, _meaning in LEGEND]
    assert len(set(legend)) == len(legend)
    # the five meanings the outputs draw, and the Rerun detection no longer in the recomputed blue
    assert {DETECTION_COLOR, RECOMPUTED_COLOR, AS_RUN_COLOR, CORRECTED_COLOR, ERROR_COLOR, STALE_COLOR,
            REFERENCE_COLOR} <= set(legend)
    # a fault's line and a hop's series never take a legend colour (red stays "unexplained")
    assert not set(FAULT_COLORS.values()) & set(legend)
    assert not set(HOP_COLORS.values()) & set(legend)
    assert len(set(FAULT_COLORS.values())) == len(FAULT_COLORS)
    text = legend_text()
    assert "orange: as-run" in text
    assert "purple: corrected" in text
    assert "green: the detection" in text
    # One palette: a fault's colour, a hop's and a meaning's are never the same, every fault has one, and the
    # legend names each (the lines between points and the hop series are explained, not only the meanings).
    assert len(set(HOP_COLORS.values())) == len(HOP_COLORS)
    assert not set(HOP_COLORS.values()) & set(FAULT_COLORS.values())
    assert set(FAULT_COLORS) == {f.value for f in Fault}
    for name, rgb in [*FAULT_COLORS.items(), *((h.value, c) for h, c in HOP_COLORS.items())]:
        assert f"{name} {'#{:02x}{:02x}{:02x}'.format(*rgb)}" in text
    # "as recorded" is not drawn in red: red is an error no finding explains
    assert RECORDED_ERROR_COLOR not in (ERROR_COLOR, STALE_COLOR)
