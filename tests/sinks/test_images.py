"""Camera images in the Rerun recording, with the chain drawn on them, read back from the .rrd.

Logs are written with the real writers (the scene generator through write_log, rosbags for the
real bag is the bag itself, the LeRobot writer plus an H.264 mp4 made with PyAV); projections are
checked against OpenCV's projectPoints, video frame references against the mp4's own frame times
as Rerun's AssetVideo reads them.
"""

from __future__ import annotations

import io
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader
from scipy.spatial.transform import Rotation

from framechain.adapters import write_log
from framechain.analysis.run import Run as PipelineRun
from framechain.analysis.verdict.attribute import Attribution
from framechain.cli.demo_cmd import parse_fault
from framechain.config.chain import ChainConfig
from framechain.pipeline import run
from framechain.replay import ReplayResult
from framechain.sim.logs import write_scene
from framechain.sim.scene import Scene, SceneSpec, generate
from framechain.sinks.colors import FAULT_COLORS
from framechain.sinks.overlay import ImageSelection
from framechain.sinks.rerun import RerunOptions, RerunTarget, stream_replay
from framechain.sinks.rerun_common import RERUN_PIXEL_OFFSET
from framechain.timeline import CameraTable, ImageFrameTable, ObservationTable, PointRole, Timeline, TransformTable
from tests.helpers.realdata import ARUCO_IMAGES_BAG
from tests.helpers.rrd_views import read_chunks

Batches = dict[str, list[tuple[bool, pa.RecordBatch]]]


def _rows(batches: Batches, entity: str, column: str) -> tuple[np.ndarray, list[Any]]:
    """(stamp ns, values) of the temporal rows of ``entity``, in stamp order (``sensor_time``; an episode's
    ``episode_time``)."""
    times: list[int] = []
    values: list[Any] = []
    for static, batch in batches.get(entity, []):
        if static or column not in batch.schema.names:
            continue
        stamps = "episode_time" if "episode_time" in batch.schema.names else "sensor_time"
        times.extend(batch.column(stamps).cast(pa.int64()).to_pylist())
        values.extend(batch.column(column).to_pylist())
    order = np.argsort(times, kind="stable")
    return np.asarray(times, dtype=np.int64)[order], [values[i] for i in order]


def _camera_pose(result: ReplayResult, i: int) -> tuple[np.ndarray, np.ndarray]:
    """rvec, tvec of camera_from_world for observation ``i`` from the transforms the replay used."""
    world_from_cam = result.world_from_body.matrix()[i] @ result.body_from_cam.matrix()[i]
    cam_from_world = np.linalg.inv(world_from_cam)
    rvec, _ = cv2.Rodrigues(cam_from_world[:3, :3])
    return rvec, cam_from_world[:3, 3]


def _opencv_pixels(timeline: Timeline, result: ReplayResult, p_world: np.ndarray) -> np.ndarray:
    cams = timeline.cameras
    k, dist = cams.K[0], cams.distortion[0, : max(int(cams.n_distortion[0]), 5)]
    out = np.full((len(p_world), 2), np.nan)
    for i, p in enumerate(p_world):
        if np.isfinite(p).all() and bool(result.replayed[i]):
            rvec, tvec = _camera_pose(result, i)
            if (cv2.Rodrigues(rvec)[0] @ p + tvec)[2] > 0:
                out[i] = cv2.projectPoints(p.reshape(1, 1, 3), rvec, tvec, k, dist)[0].reshape(2)
    return out


# ----------------------------------------------------------------------------------------------
# The demo scene: JPEG colour images, a missing rotation and a pose latency


@dataclass(frozen=True)
class Run:
    scene: Scene
    loaded: PipelineRun
    attribution: Attribution
    rrd: Path
    batches: Batches


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Run:
    out = tmp_path_factory.mktemp("demo")
    spec = SceneSpec(seed=5, duration_s=1.5, width=160, height=120, focal_px=150.0, color_images=True,
                     faults=(parse_fault("missing_rotation"), parse_fault("latency:-0.03")))
    scene = generate(spec)
    write_scene(scene, out / "episode.mcap")
    (out / "chain.yaml").write_text(scene.chain.to_yaml())
    loaded = run(out / "episode.mcap", out / "chain.yaml", seed=0)
    attribution = loaded.attributed()
    rrd = out / "episode.rrd"
    stream_replay(loaded, RerunTarget.save(rrd))
    return Run(scene, loaded, attribution, rrd, read_chunks(rrd))


def test_demo_images_are_the_logged_jpegs_at_their_stamps(demo: Run) -> None:
    images = demo.loaded.timeline.image_frames
    obs = demo.loaded.timeline.observations
    assert len(images) == len(obs) > 20  # the generator renders one image per detection
    stamps, blobs = _rows(demo.batches, "/camera/image", "EncodedImage:blob")
    media = _rows(demo.batches, "/camera/image", "EncodedImage:media_type")[1]
    # near (the default): every image within 50 ms of an observation, here all of them, at their stamps
    assert np.array_equal(stamps, np.sort(images.stamp_ns))
    assert {m[0] for m in media} == {"image/jpeg"}
    by_stamp = {int(s): i for i, s in enumerate(images.stamp_ns)}
    for stamp, blob in zip(stamps.tolist(), blobs, strict=True):
        logged = images.load(by_stamp[stamp])
        assert bytes(blob[0]) == logged  # not re-encoded
        assert logged.startswith(b"\xff\xd8\xff")
    # the image is drawn under the pinhole's image plane
    frames = [b.column("CoordinateFrame:frame").to_pylist() for s, b in demo.batches["/camera/image"] if s]
    assert frames == [[["camera_optical_frame_image_plane"]]]


def test_demo_projected_points_match_opencv(demo: Run) -> None:
    timeline, result = demo.loaded.timeline, demo.attribution.replay
    obs = result.observations
    stamps, recomputed = _rows(demo.batches, "/camera/overlay/recomputed", "Points2D:positions")
    assert np.array_equal(stamps, np.sort(obs.stamp_ns[result.replayed]))
    # Rerun's image space puts (0, 0) at the top-left pixel's corner: OpenCV's pixels are drawn half a pixel on
    got = np.array([r[0] for r in recomputed]) - RERUN_PIXEL_OFFSET
    order = np.argsort(obs.stamp_ns, kind="stable")
    expected = _opencv_pixels(timeline, result, result.p_world)[order]
    np.testing.assert_allclose(got, expected, atol=2e-3)  # float32 in the recording
    # the recomputed world point lands back on the detection, inside the 160 x 120 image
    np.testing.assert_allclose(got, np.stack([obs.u, obs.v], axis=1)[order], atol=2e-3)
    assert ((got > -0.5) & (got < [159.5, 119.5])).all()
    # as-run: the robot's own world points (the generator's, not the aligner's) through the same pose
    robot_world = demo.scene.robot_world[obs.obs_id]
    _, as_run = _rows(demo.batches, "/camera/overlay/as_run", "Points2D:positions")
    expected_as_run = _opencv_pixels(timeline, result, robot_world)[order]
    np.testing.assert_allclose(np.array([r[0] for r in as_run]) - RERUN_PIXEL_OFFSET, expected_as_run, atol=2e-2)
    # a 30 deg rotation lost: the as-run point is far from the detection (tens of pixels at 150 px focal)
    assert np.linalg.norm(expected_as_run - got, axis=1).min() > 20


def test_demo_error_line_coloured_by_the_explaining_finding(demo: Run) -> None:
    top = max(demo.attribution.findings, key=lambda f: f.share)
    assert top.fault.value == "missing_rotation"
    _, strips = _rows(demo.batches, "/camera/overlay/error", "LineStrips2D:strips")
    _, colors = _rows(demo.batches, "/camera/overlay/error", "LineStrips2D:colors")
    _, labels = _rows(demo.batches, "/camera/overlay/error", "LineStrips2D:labels")
    r, g, b = FAULT_COLORS["missing_rotation"]
    assert {c[0] for c in colors} == {(r << 24) | (g << 16) | (b << 8) | 0xFF}
    assert all("missing_rotation on camera_to_body" in lab[0] for lab in labels)
    _, recomputed = _rows(demo.batches, "/camera/overlay/recomputed", "Points2D:positions")
    _, as_run = _rows(demo.batches, "/camera/overlay/as_run", "Points2D:positions")
    for strip, a, c in zip(strips, recomputed, as_run, strict=True):
        np.testing.assert_allclose(strip[0], [a[0], c[0]], atol=1e-3)
    # the per-observation length of that line as a series
    _, px = _rows(demo.batches, "/series/error_px/as_run", "Scalars:scalars")
    lengths = [np.linalg.norm(np.subtract(c[0], a[0])) for a, c in zip(recomputed, as_run, strict=True)]
    np.testing.assert_allclose([p[0] for p in px], lengths, rtol=1e-4)


def test_demo_blueprint_puts_the_camera_beside_the_3d_view(demo: Run) -> None:
    reader = RrdReader(demo.rrd)
    origins: dict[str, str] = {}
    kinds: dict[str, str] = {}
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            if "ViewBlueprint:class_identifier" in batch.schema.names:
                kinds[chunk.entity_path] = batch.column("ViewBlueprint:class_identifier").to_pylist()[-1][0]
                origins[chunk.entity_path] = batch.column("ViewBlueprint:space_origin").to_pylist()[-1][0]
    two_d = [p for p, k in kinds.items() if k == "2D" and origins[p] == "/camera"]
    # the camera (image and overlay); no depth view: this scene's depth comes with its detections, not as images
    assert len(two_d) == 1
    assert "3D" in kinds.values()
    assert "TimeSeries" in kinds.values()


def test_demo_shows_no_view_without_data_and_names_only_its_chain_frames(demo: Run) -> None:
    from tests.helpers.rrd_views import labels_in_3d, views_without_data

    assert views_without_data(demo.rrd) == []
    frames = demo.scene.chain.frames
    assert sorted(labels_in_3d(demo.rrd)) == sorted({frames.world, frames.body, frames.camera})


def test_images_none_and_all(demo: Run, tmp_path: Path) -> None:
    timeline, replayed = demo.loaded.timeline, replace(demo.loaded, attribution=None)  # the images, no findings
    for selection, expected in ((ImageSelection.NONE, 0), (ImageSelection.ALL, len(timeline.image_frames))):
        rrd = tmp_path / f"{selection.value}.rrd"
        stream_replay(replayed, RerunTarget.save(rrd), options=RerunOptions(images=selection))
        stamps, _ = _rows(read_chunks(rrd), "/camera/image", "EncodedImage:blob")
        assert stamps.size == expected


# ----------------------------------------------------------------------------------------------
# Raw sensor_msgs/Image encodings through a real ROS 2 MCAP


def _raw_scene(encoding: str) -> tuple[Timeline, ChainConfig, np.ndarray]:
    """Two 6 x 8 images of ``encoding``, a camera at the world origin looking along +x, one detection."""
    rng = np.random.default_rng(3)
    shapes = {"mono8": (2, 6, 8), "mono16": (2, 6, 8), "16UC1": (2, 6, 8), "32FC1": (2, 6, 8),
              "rgb8": (2, 6, 8, 3), "bgr8": (2, 6, 8, 3)}
    dtype = {"mono16": np.uint16, "16UC1": np.uint16, "32FC1": np.float32}.get(encoding, np.uint8)
    pixels = (rng.uniform(0, 200, shapes[encoding])).astype(dtype)
    t0 = 1_700_000_000_000_000_000
    stamps = np.array([t0, t0 + 100_000_000])
    optical = Rotation.from_euler("xyz", [-np.pi / 2, 0, -np.pi / 2]).as_quat()
    tf = TransformTable.concat([
        TransformTable.from_rows("map", "base_link", stamps, [[0, 0, 0]] * 2, [[0, 0, 0, 1]] * 2,
                                 source="/tf"),
        TransformTable.from_rows("base_link", "cam", [t0], [[0, 0, 0]], [optical], is_static=True,
                                 source="/tf_static"),
    ])
    cams = CameraTable.from_intrinsics("cam", fx=10.0, fy=10.0, cx=3.5, cy=2.5, width=8, height=6,
                                       stamp_ns=t0, source="/cam/info")
    obs = ObservationTable(obs_id=[0], stamp_ns=[t0], log_time_ns=[t0], camera_frame=["cam"], u=[5.0], v=[2.0],
                           depth_m=[2.0], label=["x"], score=[1.0], source=["/detections"])
    images = ImageFrameTable.from_arrays("cam", stamps, pixels, encoding=encoding, source="/cam/image")
    timeline = Timeline(transforms=tf, cameras=cams, observations=obs, image_frames=images)
    chain = ChainConfig.from_dict({"frames": {"camera": "cam", "body": "base_link", "world": "map"},
                                   "topics": {"camera_info": "/cam/info", "detections": "/detections",
                                              "image": "/cam/image"}})
    return timeline, chain, pixels


@pytest.mark.parametrize("encoding", ["mono8", "mono16", "rgb8", "bgr8", "16UC1", "32FC1"])
def test_raw_encodings_become_rerun_images(encoding: str, tmp_path: Path) -> None:
    timeline, chain, pixels = _raw_scene(encoding)
    write_log(timeline, tmp_path / "raw.mcap", container="mcap-ros2", chain=chain)
    loaded = run(tmp_path / "raw.mcap", chain, attribute=False)
    images = loaded.timeline.image_frames
    assert images.encoding.tolist() == [encoding, encoding]
    assert np.array_equal(images.pixels(1), pixels[1])
    result = loaded.replay
    assert result.replayed.all()
    rrd = tmp_path / "raw.rrd"
    stream_replay(loaded, RerunTarget.save(rrd), options=RerunOptions(images=ImageSelection.ALL))
    batches = read_chunks(rrd)
    stamps, buffers = _rows(batches, "/camera/image", "Image:buffer")
    _, formats = _rows(batches, "/camera/image", "Image:format")
    assert stamps.tolist() == images.stamp_ns.tolist()
    for k in range(2):
        little_endian = pixels[k].astype(pixels.dtype.newbyteorder("<"))
        assert bytes(np.asarray(buffers[k][0], dtype=np.uint8)) == little_endian.tobytes()
        fmt = formats[k][0]
        assert (fmt["width"], fmt["height"]) == (8, 6)
    # the recomputed point lands on the detection pixel (5, 2) of the 8 x 6 image: its centre, (5.5, 2.5) in Rerun's
    # image space, where that pixel spans 5 .. 6 and 2 .. 3
    _, recomputed = _rows(batches, "/camera/overlay/recomputed", "Points2D:positions")
    np.testing.assert_allclose(recomputed[0][0], [5.5, 2.5], atol=1e-4)


# ----------------------------------------------------------------------------------------------
# The real bag: one JPEG with seven ArUco markers


@pytest.fixture(scope="module")
def aruco(
    realdata: Path, tmp_path_factory: pytest.TempPathFactory,
) -> Iterator[tuple[PipelineRun, ReplayResult, Batches, dict[str, Any]]]:
    bag = realdata / ARUCO_IMAGES_BAG
    if not bag.is_file():
        pytest.skip(f"{bag} not present")
    out = tmp_path_factory.mktemp("aruco")
    # The bag has no /tf: the chain mounts the camera 0.3 m up on the robot, looking forward.
    mount = {"parent": "base_link", "child": "raspicam", "xyz": [0.1, 0.0, 0.3], "rpy": [-np.pi / 2, 0.0, -np.pi / 2]}
    chain = {"frames": {"camera": "raspicam", "body": "base_link", "world": "map"},
             "topics": {"image": "/raspicam_node/image/compressed", "camera_info": "/raspicam_node/camera_info"},
             "evidence": {"markers": {"dictionary": "DICT_5X5_1000", "size_m": 0.14}},
             "mounts": [{"parent": "map", "child": "base_link", "xyz": [1.0, 2.0, 0.0], "rpy": [0.0, 0.0, 0.4]}, mount]}
    path = out / "chain.yaml"
    path.write_text(ChainConfig.from_dict(chain).to_yaml())
    loaded = run(bag, path, attribute=False)
    result = loaded.replay
    rrd = out / "aruco.rrd"
    stream_replay(loaded, RerunTarget.save(rrd))
    return loaded, result, read_chunks(rrd), chain


def test_real_jpeg_is_logged_as_recorded(realdata: Path,
                                         aruco: tuple[PipelineRun, ReplayResult, Batches, dict[str, Any]]) -> None:
    from rosbags.highlevel import AnyReader

    loaded, _, batches, _ = aruco
    with AnyReader([realdata / ARUCO_IMAGES_BAG]) as reader:
        conns = [c for c in reader.connections if c.topic == "/raspicam_node/image/compressed"]
        (_, _, raw), = list(reader.messages(connections=conns))
        msg = reader.deserialize(raw, conns[0].msgtype)
    stamps, blobs = _rows(batches, "/camera/image", "EncodedImage:blob")
    assert stamps.tolist() == [msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec]
    assert bytes(blobs[0][0]) == bytes(msg.data)
    assert loaded.timeline.image_frames.width.tolist() == [1280]
    assert loaded.timeline.image_frames.height.tolist() == [960]


def test_real_markers_drawn_where_opencv_projects_them(
    aruco: tuple[PipelineRun, ReplayResult, Batches, dict[str, Any]],
) -> None:
    loaded, result, batches, chain = aruco
    obs = result.observations
    assert result.replayed.all()
    assert len(obs) == 7
    # all seven markers at one stamp share one row (the viewer shows them together)
    stamps, recomputed = _rows(batches, "/camera/overlay/recomputed", "Points2D:positions")
    assert stamps.size == 1
    assert len(recomputed[0]) == 7
    got = np.array(recomputed[0])
    # OpenCV with the chain's own mounts (scipy, not framechain) and the bag's CameraInfo
    def mount(m: dict[str, Any]) -> np.ndarray:
        t = np.eye(4)
        t[:3, :3] = Rotation.from_euler("xyz", m["rpy"]).as_matrix()
        t[:3, 3] = m["xyz"]
        return t
    world_from_cam = mount(chain["mounts"][0]) @ mount(chain["mounts"][1])
    cam_from_world = np.linalg.inv(world_from_cam)
    rvec, _ = cv2.Rodrigues(cam_from_world[:3, :3])
    cams = loaded.timeline.cameras
    expected = cv2.projectPoints(result.p_world.reshape(-1, 1, 3), rvec, cam_from_world[:3, 3], cams.K[0],
                                 cams.distortion[0, :5])[0].reshape(-1, 2)
    order = np.argsort(obs.stamp_ns, kind="stable")
    np.testing.assert_allclose(got, expected[order] + RERUN_PIXEL_OFFSET, atol=5e-3)
    np.testing.assert_allclose(got, np.stack([obs.u, obs.v], axis=1)[order] + RERUN_PIXEL_OFFSET, atol=5e-3)
    assert ((got > 0) & (got < [1280, 960])).all()
    # the corners from the detector, closed quads around each marker centre
    _, corners = _rows(batches, "/camera/overlay/corners", "LineStrips2D:strips")
    quads = np.array(corners[0])
    assert quads.shape == (7, 5, 2)
    np.testing.assert_allclose(quads[:, 0], quads[:, 4])
    inside = [cv2.pointPolygonTest(q[:4].astype(np.float32), tuple(map(float, p)), False) > 0
              for q, p in zip(quads, got, strict=True)]
    assert all(inside)


# ----------------------------------------------------------------------------------------------
# A LeRobot episode with an H.264 video


def _write_mp4(path: Path, n_frames: int, fps: int, width: int, height: int) -> None:
    import av

    path.parent.mkdir(parents=True, exist_ok=True)
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=fps)
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        stream.options = {"g": "10", "bf": "0"}
        for k in range(n_frames):
            frame = np.zeros((height, width, 3), dtype=np.uint8)
            frame[:, :, 0] = (k * 9) % 255
            for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def test_lerobot_video_frames_reference_the_mp4(tmp_path: Path) -> None:
    pytest.importorskip("av")
    import rerun as rr

    from tests.helpers.lerobot_scene import FPS, HEIGHT, WIDTH, write_arm_dataset, write_robot_yaml

    lengths = (12, 15)
    dataset = write_arm_dataset(tmp_path / "ds", version="v3.0", lengths=lengths, detection_feature=True)
    video = dataset.root / "videos" / "observation.images.wrist" / "chunk-000" / "file-000.mp4"
    _write_mp4(video, sum(lengths), FPS, WIDTH // 4, HEIGHT // 4)
    robot = write_robot_yaml(tmp_path, detections=[{"feature": "observation.detection.wrist", "camera": "wrist"}])
    loaded = run(dataset.root, robot=robot, episode=1, attribute=False)
    frames = loaded.timeline.image_frames
    assert len(frames) == lengths[1]
    assert set(frames.encoding.tolist()) == {"video"}
    result = loaded.replay
    rrd = tmp_path / "ep.rrd"
    stream_replay(loaded, RerunTarget.save(rrd), options=RerunOptions(images=ImageSelection.ALL))
    batches = read_chunks(rrd)
    assets = [b for s, b in batches["/camera/video"] if s and "AssetVideo:blob" in b.schema.names]
    blob = np.asarray(assets[0].column("AssetVideo:blob").to_pylist()[0][0], dtype=np.uint8)
    assert bytes(blob) == video.read_bytes()
    stamps, refs = _rows(batches, "/camera/video", "VideoFrameReference:timestamp")
    assert stamps.tolist() == sorted(frames.stamp_ns.tolist())
    # Episode 1 starts after episode 0's 12 frames in the shared file: each reference falls on its own frame
    # of the mp4 (frame times as Rerun reads them from the file), within LeRobot's 100 us tolerance.
    pts = np.asarray(rr.AssetVideo(path=video).read_frame_timestamps_nanos(), dtype=np.int64)
    assert pts.size == sum(lengths)
    ref_ns = np.array([r[0] for r in refs], dtype=np.int64)
    want = pts[lengths[0]: lengths[0] + lengths[1]]
    assert ((ref_ns >= want) & (ref_ns - want <= 100_000)).all()
    # the detections' recomputed points are drawn on the video frames, back on the detected pixels
    obs = result.observations
    replayed = np.flatnonzero(result.replayed)
    assert replayed.size >= 10
    _, recomputed = _rows(batches, "/camera/overlay/recomputed", "Points2D:positions")
    got = np.array([r[0] for r in recomputed]) - RERUN_PIXEL_OFFSET
    order = replayed[np.argsort(obs.stamp_ns[replayed], kind="stable")]
    expected = _opencv_pixels(loaded.timeline, result, result.p_world)[order]
    np.testing.assert_allclose(got, expected, atol=5e-3)
    np.testing.assert_allclose(got, np.stack([obs.u, obs.v], axis=1)[order], atol=5e-3)
    assert ((got > -0.5) & (got < [WIDTH - 0.5, HEIGHT - 0.5])).all()


def test_each_finding_is_shown_alone(demo: Run, tmp_path: Path) -> None:
    """The latency's crops show the as-run point less what the missing rotation does: where the robot's point
    would have been with the latency alone. Independently: the same scene generated with the latency only (the
    same observations; the robot's world points carry that one fault), projected with OpenCV."""
    from framechain.sinks.overlay import FAULT_COLORS, image_overlay
    from framechain.sinks.report import finding_overlay, render_report

    attribution, timeline = demo.attribution, demo.loaded.timeline
    result = attribution.replay
    overlay = image_overlay(timeline, result, attribution.aligned, attribution.findings)
    faults = [f.fault.value for f in attribution.findings]
    assert len(attribution.others_shift) == len(faults) == 2
    for fault in faults:
        alone_faults = tuple(f for f in demo.scene.spec.faults if f.kind.value == fault)
        scene = generate(replace(demo.scene.spec, faults=alone_faults))
        assert np.array_equal(scene.timeline.observations.stamp_ns, timeline.observations.stamp_ns)
        expected = _opencv_pixels(timeline, result, scene.robot_world)
        shown, alone = finding_overlay(demo.loaded, overlay, faults.index(fault))
        assert alone
        assert shown.color == FAULT_COLORS[fault]
        assert shown.label() == f"{fault} on {attribution.findings[faults.index(fault)].hop.value}"
        ok = np.isfinite(expected).all(axis=1)
        assert ok.mean() > 0.9
        gap = np.linalg.norm(shown.as_run_uv[ok] - expected[ok], axis=1)
        own = np.linalg.norm(expected[ok] - shown.recomputed_uv[ok], axis=1)
        assert np.median(gap) < 0.1 * np.median(own)  # the finding's own effect, not the whole gap
        if fault == "latency":  # a few pixels where the whole gap is some ninety
            assert np.median(own) < 5
            assert np.nanmedian(overlay.error_px) > 50
    page = render_report(demo.loaded, tmp_path, formats=("html",))["html"].read_text()
    assert "latency on body_to_world alone: where body_to_world departs most" in page
    assert "zoomed in around the points" in page  # the latency's few pixels, shown where they can be seen


def test_report_shows_the_camera_crops_with_the_overlay(demo: Run, tmp_path: Path) -> None:
    from PIL import Image

    from framechain.sinks.colors import AS_RUN_COLOR, DETECTION_COLOR, RECOMPUTED_COLOR
    from framechain.sinks.overlay import (
        image_overlay,
        render_crops,
        worst_rows,
    )
    from framechain.sinks.report import render_report

    paths = render_report(demo.loaded, tmp_path)
    page = paths["html"].read_text()
    assert "What the camera saw" in page
    faults = [f.fault.value for f in demo.attribution.findings]
    assert set(faults) == {"missing_rotation", "latency"}
    for fault in faults:  # a section of crops per finding
        assert len(sorted(tmp_path.glob(f"camera_{fault}_obs_*.png"))) == 4
    assert "### missing_rotation on camera_to_body alone: where camera_to_body departs most" in paths["md"].read_text()
    # missing_rotation's crops are at the observations where camera_to_body departs most
    timeline, result = demo.loaded.timeline, demo.attribution.replay
    overlay = image_overlay(timeline, result, demo.attribution.aligned, demo.attribution.findings)
    departure = demo.attribution.hop_errors["camera_to_body"]
    rows = worst_rows(timeline, result, overlay, departure)
    assert departure[rows].min() >= np.percentile(departure, 60)
    ids = {int(p.stem.rsplit("_", 1)[1]) for p in tmp_path.glob("camera_missing_rotation_obs_*.png")}
    assert ids == set(result.observations.obs_id[rows].tolist())
    assert np.diff(rows).min() >= len(result) // 8  # spread over the episode
    for i, png in render_crops(timeline, overlay, rows, width_px=320):
        picture = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=int)

        def centroid(color: tuple[int, int, int], picture: np.ndarray = picture) -> np.ndarray:
            ys, xs = np.nonzero(np.abs(picture - color).max(axis=2) <= 30)
            assert xs.size > 0, color
            return np.array([xs.mean(), ys.mean()])

        # the blue (recomputed) and orange (as-run) dots point the way the projected points do ...
        recomputed, as_run = centroid(RECOMPUTED_COLOR), centroid(AS_RUN_COLOR)
        drawn = as_run - recomputed
        expected = overlay.as_run_uv[i] - overlay.recomputed_uv[i]
        cos = drawn @ expected / np.linalg.norm(drawn) / np.linalg.norm(expected)
        assert cos > np.cos(np.radians(2.0))
        # ... at the scale of the image (160 px wide: the crop's width over the canvas it spans) ...
        assert np.linalg.norm(drawn) / np.linalg.norm(expected) == pytest.approx(320 / 160, rel=0.05)
        # ... joined by a line in the explaining finding's colour
        mid = np.rint((recomputed + as_run) / 2).astype(int)
        assert np.abs(picture[mid[1], mid[0]] - FAULT_COLORS["missing_rotation"]).max() <= 40
        # and the recomputed dot sits on the drawn object (the generator's red disc is under it)
        x, y = np.rint(recomputed).astype(int)
        ring = picture[y - 12: y + 13, x - 12: x + 13].reshape(-1, 3)
        assert (np.abs(ring - DETECTION_COLOR).max(axis=1) <= 40).any()


def _by_obs(batches: Batches, entity: str) -> dict[int, float]:
    """Scalar per observation row (``obs_index``) of a series."""
    out: dict[int, float] = {}
    for static, batch in batches.get(entity, []):
        if static or "Scalars:scalars" not in batch.schema.names:
            continue
        for i, v in zip(batch.column("obs_index").to_pylist(), batch.column("Scalars:scalars").to_pylist(),
                        strict=True):
            out[int(i)] = float(v[0])
    return out


def test_demo_per_hop_error_is_each_hops_own_as_in_the_report(demo: Run) -> None:
    """Each hop's series is that hop's own departure, the report's ``hop_errors`` (computed by the attribution from
    the robot's logged input to the hop), not the error accumulated upstream that it drew before: the lost
    30 deg mount rotation moves the body point by decimetres; body_to_world itself carries only the latency."""
    result = demo.attribution
    rows = {int(o): i for i, o in enumerate(demo.loaded.replay.observations.obs_id)}
    at = np.array([rows[int(o)] for o in result.inputs.obs_id])
    for hop in ("camera_to_body", "body_to_world"):
        plotted = _by_obs(demo.batches, f"/series/error_mm/{hop}")
        got = np.array([plotted.get(int(i), np.nan) for i in at])
        np.testing.assert_allclose(got, result.hop_errors[hop] * 1e3, rtol=1e-4, atol=1e-3)
    own = np.nanmedian(result.hop_errors["body_to_world"]) * 1e3
    accumulated = np.nanmedian(np.linalg.norm(demo.loaded.aligned.points(PointRole.HOP_WORLD)
                                              - demo.loaded.replay.p_world, axis=1)) * 1e3
    assert own < 0.1 * accumulated
    # the error the findings explain, and what remains, as series beside them
    world = _by_obs(demo.batches, "/series/error_mm/world_error")
    np.testing.assert_allclose([world[int(i)] for i in at], result.error_before * 1e3, rtol=1e-4)
    corrected = _by_obs(demo.batches, "/series/error_mm/corrected")
    assert np.nanmedian(list(corrected.values())) < 0.5 * np.nanmedian(list(world.values()))
