"""The Rerun sink: save an .rrd, read it back with Rerun's own reader, check what it holds."""

from __future__ import annotations

import subprocess
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader
from scipy.spatial.transform import Rotation

from framechain.analysis.evidence.alignment import align_evidence
from framechain.analysis.model.estimates import LatencyEstimate, RotationEstimate
from framechain.analysis.verdict.attribute import Finding
from framechain.catalogue import Fault, HopName
from framechain.cli.main import main
from framechain.replay import ReplayResult, TransformBuffer, replay
from framechain.sinks.colors import DETECTION_COLOR, FAULT_COLORS
from framechain.sinks.rerun import (
    FindingView,
    OutputMode,
    RerunOptions,
    RerunSinkError,
    RerunTarget,
    display_available,
    resolve_target,
    stream_replay,
)
from framechain.timeline import (
    PointRole,
    Timeline,
    TransformTable,
)
from tests.helpers.realdata import NAV2_MCAP
from tests.helpers.rerun_scene import (
    BODY_OFFSET,
    FRAMES,
    MAP_FROM_ODOM,
    T0,
    mast_camera_timeline,
    recorded_timeline,
    replayed_run,
    with_as_run,
)
from tests.helpers.rerun_server import GrpcServer, free_port, received_entities, rerun_executable
from tests.helpers.rrd_views import Chunks, column_values, read_chunks

REFERENCE_POINT = (2.0, 0.5, 0.2)


@dataclass(frozen=True)
class Scene:
    timeline: Timeline
    result: ReplayResult
    rrd: Path
    chunks: dict[str, list[tuple[bool, pa.RecordBatch]]]


FINDINGS = [
    Finding(fault=Fault.LATENCY, hop=HopName.BODY_TO_WORLD, estimate=LatencyEstimate(offset_s=0.031),
            interval={"offset_s": [0.0295, 0.0321]}, share=0.62, error_m=0.024, confidence=0.97,
            evidence="error grows with speed", fix="look the pose up at the image stamp",
            model="latency[body_to_world]"),
]


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Scene:
    timeline = recorded_timeline()
    made = replayed_run(timeline, findings=FINDINGS, reference_point=REFERENCE_POINT)
    result = made.replay
    rrd = tmp_path_factory.mktemp("rerun") / "scene.rrd"
    outcome = stream_replay(made, RerunTarget.save(rrd), options=RerunOptions(recording_id="scene"))
    assert outcome.mode is OutputMode.SAVE
    assert outcome.path == rrd
    assert not outcome.fell_back
    return Scene(timeline, result, rrd, read_chunks(rrd))


def _times(chunks: Chunks, entity: str, timeline: str) -> np.ndarray[Any, Any]:
    rows = column_values(chunks, entity, timeline, static=False)
    if rows and hasattr(rows[0], "value"):
        return np.array([r.value for r in rows], dtype=np.int64)
    return np.array([np.datetime64(r, "ns").astype(np.int64) if not isinstance(r, int) else r for r in rows],
                    dtype=np.int64)


def test_scene_replays_as_designed(scene: Scene) -> None:
    counts = scene.result.counts()
    assert counts["total"] == 7
    assert counts["replayed"] == 5
    assert counts["rejected"] == {"extrapolation": 1, "outside_image": 1}


def test_entity_paths_and_frame_names_exist(scene: Scene) -> None:
    for entity in ("/tf/base_link", "/tf/odom", "/tf/mast_link", "/tf/camera_optical_frame",
                   "/replay/world_from_body", "/replay/body_from_cam", "/camera", "/camera/depth",
                   "/camera/detections", "/points/recomputed/camera", "/points/recomputed/body",
                   "/points/recomputed/world", "/points/as_run/camera", "/points/as_run/body",
                   "/points/as_run/world", "/points/as_run/target", "/points/error/body", "/points/error/world",
                   "/points/reference/declared", "/points/reference/matched", "/log/findings", "/log/rejected",
                   "/summary", "/frames/map", "/frames/camera_optical_frame", "/frames/replay/base_link",
                   "/frames/replay/camera_optical_frame"):
        assert entity in scene.chunks, entity
    children = {c[0] for e in ("/tf/base_link", "/tf/odom", "/tf/mast_link", "/tf/camera_optical_frame")
                for c in column_values(scene.chunks, e, "Transform3D:child_frame")}
    parents = {p[0] for e in ("/tf/base_link", "/tf/odom", "/tf/mast_link", "/tf/camera_optical_frame")
               for p in column_values(scene.chunks, e, "Transform3D:parent_frame")}
    assert children == {"base_link", "odom", "mast_link", "camera_optical_frame"}
    assert parents == {"map", "odom", "base_link", "mast_link"}
    assert column_values(scene.chunks, "/points/recomputed/world", "CoordinateFrame:frame") == [["map"]]
    assert column_values(scene.chunks, "/frames/replay/base_link", "CoordinateFrame:frame") == [["base_link@replay"]]
    camera_frame = column_values(scene.chunks, "/points/recomputed/camera", "CoordinateFrame:frame")
    assert camera_frame == [["camera_optical_frame@replay"]]
    detections_frame = column_values(scene.chunks, "/camera/detections", "CoordinateFrame:frame")
    assert detections_frame == [["camera_optical_frame_image_plane"]]
    pinhole_parent = column_values(scene.chunks, "/camera", "Pinhole:parent_frame")
    assert pinhole_parent == [["camera_optical_frame"]]
    assert column_values(scene.chunks, "/camera", "Pinhole:child_frame") == [["camera_optical_frame_image_plane"]]
    # K is stored column-major; the principal point moves half a pixel as the pixels drawn do (Rerun puts (0, 0) at
    # the top-left pixel's corner, OpenCV at its centre): fx 150 and cx 80 of the scene become cx 80.5.
    k = np.asarray(column_values(scene.chunks, "/camera", "Pinhole:image_from_camera")[0][0]).reshape(3, 3).T
    np.testing.assert_allclose(k, [[150.0, 0.0, 80.5], [0.0, 150.0, 60.5], [0.0, 0.0, 1.0]])


def test_world_points_equal_the_replay(scene: Scene) -> None:
    ok = np.flatnonzero(scene.result.replayed)
    logged = np.array([r[0] for r in column_values(scene.chunks, "/points/recomputed/world", "Points3D:positions")])
    np.testing.assert_allclose(logged, scene.result.p_world[ok], rtol=1e-6, atol=1e-6)
    assert np.array_equal(logged, scene.result.p_world[ok].astype(np.float32))
    assert np.array_equal(_times(scene.chunks, "/points/recomputed/world", "obs_index"), ok)
    assert np.array_equal(_times(scene.chunks, "/points/recomputed/world", "sensor_time"),
                          scene.result.observations.stamp_ns[ok])
    assert np.array_equal(_times(scene.chunks, "/points/recomputed/world", "log_time"),
                          scene.result.observations.log_time_ns[ok])
    body = np.array([r[0] for r in column_values(scene.chunks, "/points/recomputed/body", "Points3D:positions")])
    np.testing.assert_allclose(body, scene.result.p_body[ok], rtol=1e-6, atol=1e-6)


def test_as_run_points_are_matched_and_offset(scene: Scene) -> None:
    ok = np.flatnonzero(scene.result.replayed)
    as_run_world = np.array([r[0] for r in column_values(scene.chunks, "/points/as_run/world", "Points3D:positions")])
    # Logged in odom, matched by stamp 0.2 ms away, brought back into map.
    np.testing.assert_allclose(as_run_world, scene.result.p_world[ok] + BODY_OFFSET, atol=1e-5)
    arrows = np.array([r[0] for r in column_values(scene.chunks, "/points/error/body", "Arrows3D:vectors")])
    np.testing.assert_allclose(arrows, np.tile(BODY_OFFSET, (ok.size, 1)), atol=1e-6)
    camera = np.array([r[0] for r in column_values(scene.chunks, "/points/error/camera", "Arrows3D:vectors")])
    np.testing.assert_allclose(camera, 0.0, atol=1e-7)  # the camera hop agrees: zero-length arrows
    # The arrows take the colour of the finding that explains them, as the line in the image does (red is only an
    # error no finding explains): the latency's gold, packed RGBA.
    colours = {r[0] for r in column_values(scene.chunks, "/points/error/body", "Arrows3D:colors")}
    r, g, b = FAULT_COLORS["latency"]
    assert colours == {(r << 24) | (g << 16) | (b << 8) | 0xFF}


def test_used_transforms_logged_at_observation_times(scene: Scene) -> None:
    ok = np.flatnonzero(scene.result.replayed)
    t = np.array([r[0] for r in column_values(scene.chunks, "/replay/world_from_body", "Transform3D:translation")])
    np.testing.assert_allclose(t, scene.result.world_from_body.translation[ok], rtol=1e-6, atol=1e-6)
    q = np.array([r[0] for r in column_values(scene.chunks, "/replay/body_from_cam", "Transform3D:quaternion")])
    dots = np.abs(np.sum(q * scene.result.body_from_cam.quat_xyzw[ok], axis=1))
    np.testing.assert_allclose(dots, 1.0, atol=1e-6)
    assert np.array_equal(_times(scene.chunks, "/replay/world_from_body", "sensor_time"),
                          scene.result.observations.stamp_ns[ok])
    assert column_values(scene.chunks, "/replay/world_from_body", "Transform3D:child_frame")[0] == ["base_link@replay"]
    assert column_values(scene.chunks, "/replay/body_from_cam", "Transform3D:parent_frame")[0] == ["base_link@replay"]


def test_static_edges_are_static_and_dynamic_edges_bulk(scene: Scene) -> None:
    for entity in ("/tf/odom", "/tf/mast_link", "/tf/camera_optical_frame"):
        assert all(static for static, _ in scene.chunks[entity]), entity
        assert len(column_values(scene.chunks, entity, "Transform3D:translation")) == 1
    assert not any(static for static, _ in scene.chunks["/tf/base_link"])
    tf = scene.timeline.transforms
    dynamic = tf.take(tf.child == "base_link")
    translations = np.array([r[0] for r in column_values(scene.chunks, "/tf/base_link", "Transform3D:translation")])
    assert translations.shape == (len(dynamic), 3)
    np.testing.assert_allclose(translations, dynamic.translation, rtol=1e-6, atol=1e-6)
    assert np.array_equal(_times(scene.chunks, "/tf/base_link", "sensor_time"), dynamic.stamp_ns)
    assert np.array_equal(_times(scene.chunks, "/tf/base_link", "log_time"), dynamic.log_time_ns)


def test_per_hop_series_have_one_row_per_replayed_observation(scene: Scene) -> None:
    result = scene.result
    ok = np.flatnonzero(result.replayed)
    for hop in ("pixel_to_camera", "camera_to_body", "body_to_world"):
        for kind in ("error_mm", "gap_ms"):
            values = column_values(scene.chunks, f"/series/{kind}/{hop}", "Scalars:scalars")
            assert len(values) == ok.size, (kind, hop)
            assert np.array_equal(_times(scene.chunks, f"/series/{kind}/{hop}", "obs_index"), ok)
        gaps = np.array([v[0] for v in column_values(scene.chunks, f"/series/gap_ms/{hop}", "Scalars:scalars")])
        sel = (result.hops.hop == hop) & (result.hops.status == "replayed")
        np.testing.assert_allclose(gaps, result.hops.gap_ns[sel] / 1e6)
    errors = {hop: np.array([v[0] for v in column_values(scene.chunks, f"/series/error_mm/{hop}", "Scalars:scalars")])
              for hop in ("pixel_to_camera", "camera_to_body", "body_to_world", "target")}
    np.testing.assert_allclose(errors["pixel_to_camera"], 0.0, atol=1e-9)
    np.testing.assert_allclose(errors["camera_to_body"], 50.0, atol=1e-6)
    # Each hop's own error: the robot's world point is its body point (off by 5 cm along the body's x) taken through
    # the pose, against the same 5 cm added along the map's x: the hop differs by (I - R_map_body) * 5 cm, not the
    # 50 mm accumulated upstream (what the series plotted under this label before).
    t_s = (result.observations.stamp_ns[ok] - T0) / 1e9
    map_from_body = MAP_FROM_ODOM * Rotation.from_euler("z", 0.2 * t_s[:, None])
    own = np.linalg.norm(BODY_OFFSET - map_from_body.apply(BODY_OFFSET), axis=1) * 1e3
    assert (own < 30).all()
    np.testing.assert_allclose(errors["body_to_world"], own, atol=1e-3)
    np.testing.assert_allclose(errors["target"], 30.0, atol=1e-6)
    reference = np.array([v[0] for v in column_values(scene.chunks, "/series/error_mm/reference", "Scalars:scalars")])
    np.testing.assert_allclose(reference, np.linalg.norm(result.p_world[ok] - REFERENCE_POINT, axis=1) * 1e3)


def test_text_log_has_findings_rejections_and_summary(scene: Scene) -> None:
    findings = [r[0] for r in column_values(scene.chunks, "/log/findings", "TextLog:text")]
    assert findings == [FindingView.of(FINDINGS[0]).text()]
    assert "latency on body_to_world" in findings[0]
    assert "estimate +31.0 ms (95% interval +29.50 .. +32.10 ms)" in findings[0]
    assert "62% of the error" in findings[0]
    assert "24.0 mm" in findings[0]
    rejected = [r[0] for r in column_values(scene.chunks, "/log/rejected", "TextLog:text")]
    assert len(rejected) == 2
    assert any("outside_image" in r for r in rejected)
    assert any("extrapolation on body_to_world (map <- base_link)" in r for r in rejected)
    assert column_values(scene.chunks, "/log/rejected", "TextLog:level") == [["WARN"], ["WARN"]]
    summary = column_values(scene.chunks, "/summary", "TextDocument:text")[0][0]
    assert "| replayed | 5 |" in summary
    assert "| rejected: extrapolation | 1 |" in summary


def test_camera_images_and_detections(scene: Scene) -> None:
    images = column_values(scene.chunks, "/camera/depth", "DepthImage:buffer")
    ok = scene.result.replayed
    used = np.unique(scene.result.depth_stamp_ns[ok & ~np.isfinite(scene.result.observations.depth_m)])
    assert 1 <= len(images) <= len(scene.timeline.depth_frames)
    assert set(used.tolist()) <= set(_times(scene.chunks, "/camera/depth", "sensor_time").tolist())
    first = np.frombuffer(bytes(images[0][0]), dtype=np.uint16)  # millimetres
    assert first.size == 160 * 120
    assert column_values(scene.chunks, "/camera/depth", "DepthImage:meter")[0] == [1000.0]
    first_stamp = _times(scene.chunks, "/camera/depth", "sensor_time")[0]
    row = int(np.flatnonzero(scene.timeline.depth_frames.stamp_ns == first_stamp)[0])
    expected = scene.timeline.depth_frames.load(row)
    np.testing.assert_allclose(first.reshape(120, 160) / 1000.0, expected, atol=5e-4)
    detections = np.array([r[0] for r in column_values(scene.chunks, "/camera/detections", "Points2D:positions")])
    obs = scene.result.observations
    # OpenCV's pixel (80, 60), the centre of pixel column 80 and row 60, is (80.5, 60.5) in Rerun's image space,
    # where pixel 80 spans 80 .. 81
    np.testing.assert_allclose(detections[0], [80.5, 60.5])
    np.testing.assert_allclose(detections, np.stack([obs.u, obs.v], axis=1) + 0.5)
    # not the recomputed blue: the detector's own pixel, in the detection's green
    colors = [c for r in column_values(scene.chunks, "/camera/detections", "Points2D:colors") for c in r]
    ok = scene.result.replayed & ~scene.result.stale
    r, g, b = DETECTION_COLOR
    assert {c for c, good in zip(colors, ok, strict=True) if good} == {(r << 24) | (g << 16) | (b << 8) | 0xFF}


def test_rerun_verifies_the_recording(scene: Scene) -> None:
    """Rerun's own `rrd verify`: every component decodes and the footer is well formed."""
    exe = rerun_executable()
    if exe is None:
        pytest.skip("the rerun executable is not installed")
    done = subprocess.run([exe, "rrd", "verify", "--check-footers", "true", str(scene.rrd)],
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "verified without error" in done.stdout + done.stderr


def test_depth_frames_are_decimated(tmp_path: Path, scene: Scene) -> None:
    rrd = tmp_path / "few.rrd"
    stream_replay(replayed_run(scene.timeline), RerunTarget.save(rrd), options=RerunOptions(max_images=2))
    chunks = [c for c in RrdReader(rrd).stream() if c.entity_path == "/camera/depth" and not c.is_static]
    assert sum(c.num_rows for c in chunks) == 2


def test_blueprint_is_present_with_world_target_frame(scene: Scene) -> None:
    reader = RrdReader(scene.rrd)
    assert len(reader.recordings()) == 1
    blueprints = reader.blueprints()
    assert len(blueprints) == 1
    names: dict[str, list[Any]] = defaultdict(list)
    for chunk in reader.stream(store=blueprints[0]):
        batch = chunk.to_record_batch()
        for col in batch.schema.names:
            names[col].extend(batch.column(col).to_pylist())
    assert ["map"] in names["SpatialInformation:target_frame"]
    assert ["camera_optical_frame_image_plane"] in names["SpatialInformation:target_frame"]
    classes = {c[0] for c in names["ViewBlueprint:class_identifier"]}
    assert {"3D", "2D", "TimeSeries", "TextLog"} <= classes


def test_spawn_without_display_falls_back_to_saving(
    tmp_path: Path, scene: Scene, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert not display_available()
    fallback = tmp_path / "fallback.rrd"
    outcome = stream_replay(replayed_run(scene.timeline), RerunTarget.spawn(fallback))
    assert outcome.mode is OutputMode.SAVE
    assert outcome.fell_back
    assert outcome.path == fallback
    err = capsys.readouterr().err
    assert "no display" in err
    assert str(fallback) in err
    assert "/points/recomputed/world" in {c.entity_path for c in RrdReader(fallback).stream()}


def test_resolve_target_keeps_spawn_with_a_display() -> None:
    target = RerunTarget.spawn("x.rrd")
    assert resolve_target(target, env={"DISPLAY": ":0"}) == (target, None)
    assert resolve_target(target, env={"WAYLAND_DISPLAY": "wayland-0"})[0] is target
    saved, note = resolve_target(target, env={})
    assert saved.mode is OutputMode.SAVE
    assert note is not None


def test_as_run_matching_by_id_stamp_and_frame() -> None:
    timeline = mast_camera_timeline()
    result = replay(timeline, FRAMES)
    logged = with_as_run(timeline, result)
    buffer = TransformBuffer.from_timeline(logged)
    matched = align_evidence(logged.points, result.observations, FRAMES, buffer)
    ok = result.replayed
    np.testing.assert_allclose(matched.points(PointRole.HOP_CAMERA)[ok], result.p_cam[ok])
    np.testing.assert_allclose(matched.points(PointRole.HOP_WORLD)[ok], result.p_world[ok] + BODY_OFFSET, atol=1e-9)
    assert np.isnan(matched.points(PointRole.HOP_WORLD)[~ok]).all()
    assert np.isnan(matched.points(PointRole.REFERENCE)).all()
    # Outside the stamp tolerance nothing matches.
    strict = align_evidence(logged.points, result.observations, FRAMES, buffer,
                            tolerances_ns={PointRole.HOP_WORLD: 100_000})
    assert np.isnan(strict.points(PointRole.HOP_WORLD)).all()
    assert np.isfinite(strict.points(PointRole.HOP_BODY)[ok]).all()  # matched by obs_id, whatever the stamp


def test_finding_view_words_a_typed_finding() -> None:
    finding = Finding(
        fault=Fault.MISSING_ROTATION, hop=HopName.CAMERA_TO_BODY,
        estimate=RotationEstimate(angle_deg=30.0, axis=(0.0, -1.0, 0.0), axis_frame="camera_link", faulty="as run"),
        interval={}, share=0.9, error_m=0.5, confidence=0.99, evidence="error grows with depth.",
        fix="use the full extrinsic", model="rotation[camera_to_body]",
    )
    text = FindingView.of(finding).text()
    assert text.startswith("missing_rotation on camera_to_body; estimate 30.00 deg about -y of camera_link; "
                           "500.0 mm, 90% of the error, confidence 0.99.")
    assert text.endswith("Evidence: error grows with depth. Fix: use the full extrinsic.")


# ----------------------------------------------------------------------------------------------
# Connect: a headless Rerun gRPC server that saves what it receives (no viewer, no display)


# The server's file is a stream without footer; Rerun's reader says so and scans the whole file.
@pytest.mark.filterwarnings("ignore:RRD file has no footer:rerun.error_utils.RerunWarning")
def test_connect_sends_to_a_running_server(scene: Scene, grpc_server: GrpcServer) -> None:
    outcome = stream_replay(replayed_run(scene.timeline), RerunTarget.connect(grpc_server.url))
    assert outcome.mode is OutputMode.CONNECT
    assert outcome.url == grpc_server.url
    assert outcome.path is None
    entities = received_entities(grpc_server)
    assert {"/points/recomputed/world", "/tf/base_link", "/summary"} <= entities


def test_connect_to_nothing_fails_at_once(scene: Scene) -> None:
    url = f"rerun+http://127.0.0.1:{free_port()}/proxy"
    with pytest.raises(RerunSinkError, match="no Rerun viewer listening at rerun"):
        stream_replay(replayed_run(scene.timeline), RerunTarget.connect(url), options=RerunOptions())
    with pytest.raises(RerunSinkError, match="not a Rerun gRPC URL"):
        stream_replay(replayed_run(scene.timeline), RerunTarget.connect("http://"))


def test_real_nav2_frame_tree(realdata: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A real TurtleBot 4 Nav2 MCAP (sim-time header stamps): every edge on its /tf/<child> entity."""
    from framechain.adapters import open_log

    log = realdata / NAV2_MCAP
    out = tmp_path / "nav2.rrd"
    assert main(["replay", str(log), "--save", str(out), "--quiet"]) == 0
    # No progress bar, no suggested chain: only why nothing was replayed (the frame tree is still written).
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "no detections topic in the log" in err[0]
    assert "topics.detections" in err[0]
    tf = open_log(log).timeline.transforms
    chunks = read_chunks(out)
    for child in np.unique(tf.child).tolist():
        entity = f"/tf/{child}"
        rows = tf.take(tf.child == child)
        if rows.is_static.all():
            assert all(static for static, _ in chunks[entity]), entity
            continue
        translations = np.array([r[0] for r in column_values(chunks, entity, "Transform3D:translation")])
        order = np.argsort(rows.stamp_ns, kind="stable")
        np.testing.assert_allclose(translations, rows.translation[order], rtol=1e-6, atol=1e-6)
        assert np.array_equal(_times(chunks, entity, "sensor_time"), rows.stamp_ns[order])


def test_empty_and_unreplayable_timelines_still_save(tmp_path: Path, scene: Scene) -> None:
    empty = Timeline()
    outcome = stream_replay(replayed_run(empty), RerunTarget.save(tmp_path / "empty.rrd"))
    assert outcome.rows["/summary"] == 1
    # Observations without any transform: all rejected (missing edge), each a text log entry.
    blind = replayed_run(scene.timeline.replace(transforms=TransformTable.empty()), findings=FINDINGS)
    result = blind.replay
    assert not result.replayed.any()
    out = tmp_path / "blind.rrd"
    outcome = stream_replay(blind, RerunTarget.save(out))
    chunks = read_chunks(out)
    assert len(column_values(chunks, "/log/rejected", "TextLog:text")) == len(result)
    assert "/points/recomputed/world" not in chunks
    assert "/series/gap_ms/body_to_world" not in chunks
