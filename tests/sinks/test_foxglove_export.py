"""``framechain export``: the log and the replay in one MCAP, read back with mcap's reader.

Every added message is decoded with classes built from the FileDescriptorSet stored in the file
(not framechain's or foxglove_schemas_protobuf's classes), so a wrong schema registration fails.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from framechain.cli.demo_cmd import parse_fault
from framechain.cli.main import main
from framechain.pipeline import load_log, run
from framechain.replay import replay
from framechain.sim.logs import write_scene
from framechain.sim.scene import SceneSpec, generate
from framechain.sinks.foxglove_export import (
    ANNOTATIONS_TOPIC,
    CALIBRATION_TOPIC,
    FINDINGS_TOPIC,
    SCENE_TOPIC,
    TF_TOPIC,
    clip_to_image,
)
from framechain.sinks.overlay import image_overlay
from tests.helpers.realdata import ARUCO_IMAGES_BAG, STAIRS, TF_EXAMPLE_BAG

ADDED = {TF_TOPIC: "foxglove.FrameTransforms", ANNOTATIONS_TOPIC: "foxglove.ImageAnnotations",
         SCENE_TOPIC: "foxglove.SceneUpdate", FINDINGS_TOPIC: "foxglove.Log",
         CALIBRATION_TOPIC: "foxglove.CameraCalibration"}


def _decoder(schema: Any) -> Any:
    """A message class from the schema's own FileDescriptorSet."""
    files = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    for f in files.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))


def _read(path: Path) -> tuple[Counter[str], dict[str, list[tuple[int, Any]]], dict[str, list[bytes]]]:
    copied: Counter[str] = Counter()
    added: dict[str, list[tuple[int, Any]]] = {}
    raw: dict[str, list[bytes]] = {}
    classes: dict[int, Any] = {}
    with path.open("rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            if channel.topic in ADDED:
                assert schema is not None
                assert schema.encoding == "protobuf"
                assert channel.message_encoding == "protobuf"
                assert schema.name == ADDED[channel.topic]
                if schema.id not in classes:
                    classes[schema.id] = _decoder(schema)
                decoded = classes[schema.id].FromString(message.data)
                assert decoded.SerializeToString() == message.data  # nothing unknown to the schema
                added.setdefault(channel.topic, []).append((message.log_time, decoded))
            else:
                copied[channel.topic] += 1
                raw.setdefault(channel.topic, []).append(bytes(message.data))
    return copied, added, raw


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    out = tmp_path_factory.mktemp("export")
    spec = SceneSpec(seed=9, duration_s=1.2, width=160, height=120, focal_px=150.0, color_images=True,
                     faults=(parse_fault("missing_rotation"),))
    scene = generate(spec)
    log = write_scene(scene, out / "episode.mcap")
    chain = out / "chain.yaml"
    chain.write_text(scene.chain.to_yaml())
    annotated = out / "annotated.mcap"
    assert main(["export", str(log), "--chain", str(chain), "--out", str(annotated), "-q"]) == 0
    return log, chain, annotated


def test_log_messages_copied_unchanged(demo: tuple[Path, Path, Path]) -> None:
    log, _, annotated = demo
    copied, _, raw = _read(annotated)
    original: Counter[str] = Counter()
    original_raw: dict[str, list[bytes]] = {}
    with log.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            original[channel.topic] += 1
            original_raw.setdefault(channel.topic, []).append(bytes(message.data))
    assert copied == original
    assert raw == original_raw
    assert "/camera/color/image_raw" in copied


def test_every_added_message_decodes_and_annotations_land_on_the_detection(demo: tuple[Path, Path, Path]) -> None:
    log, chain, annotated = demo
    _, added, _ = _read(annotated)
    assert set(added) == set(ADDED)
    loaded = load_log(log, chain)
    obs = loaded.timeline.observations
    images = loaded.timeline.image_frames
    assert len(added[ANNOTATIONS_TOPIC]) == len(images) == len(obs)
    by_stamp = {int(s): (float(u), float(v)) for s, u, v in zip(obs.stamp_ns, obs.u, obs.v, strict=True)}
    image_stamps = set(images.stamp_ns.tolist())
    for _, msg in added[ANNOTATIONS_TOPIC]:
        first = msg.points[0]
        stamp = first.timestamp.seconds * 10**9 + first.timestamp.nanos
        assert stamp in image_stamps  # paired with the image it is drawn on
        assert first.type == 1  # POINTS: the detection
        # OpenCV's pixel (u, v) (origin at the top-left pixel's centre) is (u + 0.5, v + 0.5) in Foxglove (its corner)
        u, v = by_stamp[stamp]
        assert (first.points[0].x, first.points[0].y) == pytest.approx((u + 0.5, v + 0.5), abs=1e-9)
        # the recomputed point (second POINTS) projects back onto the detection as well
        recomputed = [p for p in msg.points if p.type == 1][1]
        assert (recomputed.points[0].x, recomputed.points[0].y) == pytest.approx((u + 0.5, v + 0.5), abs=1e-6)
        lines = [p for p in msg.points if p.type == 4]  # LINE_LIST: recomputed -> as-run
        assert len(lines) == 1
        assert len(lines[0].points) == 2
        assert "missing_rotation on camera_to_body" in msg.texts[0].text
    findings = [m for _, m in added[FINDINGS_TOPIC]]
    assert findings
    assert findings[0].level == 4
    assert findings[0].message.startswith("missing_rotation on camera_to_body")
    result = replay(loaded.timeline, loaded.chain.frames, latency_budget_s=loaded.chain.latency_budget_s)
    tf = [m for _, m in added[TF_TOPIC]]
    assert len(tf) == int(result.replayed.sum())
    assert [t.parent_frame_id for t in tf[0].transforms] == ["map", "base_link@replay"]
    scene = [m for _, m in added[SCENE_TOPIC]]
    spheres = np.array([[s.pose.position.x, s.pose.position.y, s.pose.position.z] for m in scene
                        for s in m.entities[0].spheres[:1]])
    order = np.argsort(obs.stamp_ns, kind="stable")
    np.testing.assert_allclose(spheres, result.p_world[order], atol=1e-9)


def test_clip_to_image_hand_worked() -> None:
    """A 320x240 image spans -0.5 .. 319.5 by -0.5 .. 239.5 in OpenCV pixels."""
    start = np.array([[100.0, 50.0], [10.0, 10.0], [100.0, 50.0], [400.0, 50.0], [100.0, 50.0]])
    end = np.array([[100.0, -150.0], [-30.0, 50.0], [200.0, 60.0], [500.0, 50.0], [np.nan, np.nan]])
    width, height = np.full(5, 320), np.full(5, 240)
    clipped, cut = clip_to_image(start, end, width, height)
    assert cut.tolist() == [True, True, False, False, False]
    # straight up: 50.5 of the 200 px step reach v = -0.5
    np.testing.assert_allclose(clipped[0], [100.0, -0.5])
    # left and down: u reaches -0.5 after 10.5 / 40 of the step, v = 10 + 0.2625 * 40 = 20.5
    np.testing.assert_allclose(clipped[1], [-0.5, 20.5])
    np.testing.assert_array_equal(clipped[2:4], end[2:4])  # inside, or starting outside: kept whole
    no_image, cut = clip_to_image(start[:1], end[:1], np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64))
    assert not cut.any()
    np.testing.assert_array_equal(no_image, end[:1])


def test_as_run_points_off_the_image_end_at_its_border(demo: tuple[Path, Path, Path]) -> None:
    """The missing 30 deg pitch puts every as-run point above the picture: the line stops at the border (in
    Foxglove's pixels, y = 0), pointing at the as-run point, no dot is drawn there, and the label says where it is."""
    log, chain, annotated = demo
    _, added, _ = _read(annotated)
    made = run(log, chain, attribute=False)
    result = made.replay
    overlay = image_overlay(made.timeline, result, made.aligned)
    outside = ~overlay.inside(overlay.as_run_uv)
    assert outside.mean() > 0.9  # the case this test is about
    by_stamp = {int(s): i for i, s in enumerate(result.observations.stamp_ns.tolist())}
    for _, msg in added[ANNOTATIONS_TOPIC]:
        (line,) = [p for p in msg.points if p.type == 4]
        i = by_stamp[line.timestamp.seconds * 10**9 + line.timestamp.nanos]
        start = np.array([line.points[0].x, line.points[0].y])
        stop = np.array([line.points[1].x, line.points[1].y])
        assert 0 <= stop[0] <= 160  # within the picture, its corners at 0 and the size
        assert 0 <= stop[1] <= 120
        dots = [np.array([p.points[0].x, p.points[0].y]) for p in msg.points if p.type == 1]
        if not outside[i]:
            continue
        assert min(stop[1], 120 - stop[1], stop[0], 160 - stop[0]) == pytest.approx(0.0, abs=1e-9)
        toward = overlay.as_run_uv[i] + 0.5 - start
        along = stop - start
        assert abs(toward[0] * along[1] - toward[1] * along[0]) < 1e-6 * np.linalg.norm(toward) ** 2  # same ray
        assert len(dots) == 2  # the detection and the recomputed point; no as-run dot off the picture
        assert "as-run point off the image at" in msg.texts[0].text
        assert (msg.texts[0].position.x, msg.texts[0].position.y) == pytest.approx((stop[0], stop[1]))


def test_calibration_of_the_replay_is_exported(demo: tuple[Path, Path, Path]) -> None:
    """The camera model the replay used, once (one model), at the first annotated image, in the replay's frame."""
    _, _, annotated = demo
    _, added, _ = _read(annotated)
    (log_ns, calibration), = added[CALIBRATION_TOPIC]
    # SceneSpec(width=160, height=120, focal_px=150): fx = fy = 150, cx = 80, cy = 60, no distortion
    assert (calibration.width, calibration.height) == (160, 120)
    assert list(calibration.K) == [150.0, 0.0, 80.0, 0.0, 150.0, 60.0, 0.0, 0.0, 1.0]
    assert list(calibration.P) == [150.0, 0.0, 80.0, 0.0, 0.0, 150.0, 60.0, 0.0, 0.0, 0.0, 1.0, 0.0]
    assert calibration.frame_id == "camera_optical_frame@replay"
    first = min(m.points[0].timestamp.seconds * 10**9 + m.points[0].timestamp.nanos
                for _, m in added[ANNOTATIONS_TOPIC])
    assert calibration.timestamp.seconds * 10**9 + calibration.timestamp.nanos == first
    assert log_ns <= min(t for t, _ in added[ANNOTATIONS_TOPIC])  # there before the first annotations


def test_log_without_images_gets_a_camera(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """No image in the log: the annotations still come with a CameraCalibration to be shown on."""
    spec = SceneSpec(seed=3, duration_s=0.6, width=200, height=100, focal_px=120.0, color_images=False)
    scene = generate(spec)
    log = write_scene(scene, tmp_path / "episode.mcap")
    chain = tmp_path / "chain.yaml"
    chain.write_text(scene.chain.to_yaml())
    out = tmp_path / "annotated.mcap"
    assert main(["export", str(log), "--chain", str(chain), "--out", str(out), "--no-attribute", "-q"]) == 0
    assert (f"{ANNOTATIONS_TOPIC} on camera camera_optical_frame: no image in the log; calibration "
            f"{CALIBRATION_TOPIC}") in capsys.readouterr().out
    copied, added, _ = _read(out)
    assert not [t for t in copied if "image" in t]
    assert len(added[ANNOTATIONS_TOPIC]) == len(load_log(log, chain).timeline.observations)
    (_, calibration), = added[CALIBRATION_TOPIC]
    assert (calibration.width, calibration.height) == (200, 100)
    assert list(calibration.K) == [120.0, 0.0, 100.0, 0.0, 120.0, 50.0, 0.0, 0.0, 1.0]


def test_real_bag_copied_and_annotated(realdata: Path, tmp_path: Path) -> None:
    bag = realdata / ARUCO_IMAGES_BAG
    if not bag.is_file():
        pytest.skip(f"{bag} not present")
    chain = tmp_path / "chain.yaml"
    chain.write_text("""
frames: {camera: raspicam, body: base_link, world: map}
topics: {image: /raspicam_node/image/compressed, camera_info: /raspicam_node/camera_info}
evidence: {markers: {dictionary: DICT_5X5_1000, size_m: 0.14}}
mounts:
  - {parent: map, child: base_link, xyz: [0, 0, 0], rpy: [0, 0, 0]}
  - {parent: base_link, child: raspicam, xyz: [0.1, 0, 0.3], rpy: [-1.5707963, 0, -1.5707963]}
""")
    out = tmp_path / "annotated.mcap"
    assert main(["export", str(bag), "--chain", str(chain), "--out", str(out), "-q"]) == 0
    copied, added, raw = _read(out)
    assert copied == Counter({"/raspicam_node/camera_info": 15, "/raspicam_node/image/compressed": 1})
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == "/raspicam_node/image/compressed"]
        assert raw["/raspicam_node/image/compressed"] == [bytes(r) for _, _, r in reader.messages(connections=conns)]
    (_, annotations), = added[ANNOTATIONS_TOPIC]
    corners = [p for p in annotations.points if p.type == 2]  # LINE_LOOP: the seven markers
    assert len(corners) == 7
    (_, calibration), = added[CALIBRATION_TOPIC]  # the bag's CameraInfo, as Foxglove's CameraCalibration
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == "/raspicam_node/camera_info"]
        info: Any = reader.deserialize(next(iter(reader.messages(connections=conns)))[2], conns[0].msgtype)
    assert (calibration.width, calibration.height) == (info.width, info.height)
    np.testing.assert_array_equal(calibration.K, info.K)  # ROS 1 field names
    np.testing.assert_array_equal(calibration.D, info.D)
    assert calibration.distortion_model == info.distortion_model == "plumb_bob"
    assert calibration.frame_id == "raspicam@replay"
    with out.open("rb") as f:  # the copy keeps ROS 1 encodings, readable as ROS 1
        summary = make_reader(f).get_summary()
    assert summary is not None
    encodings = {c.topic: c.message_encoding for c in summary.channels.values()}
    assert encodings["/raspicam_node/image/compressed"] == "ros1"


def test_out_must_be_mcap_and_not_the_log(demo: tuple[Path, Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    log, chain, _ = demo
    assert main(["export", str(log), "--chain", str(chain), "--out", str(log.with_suffix(".txt")), "-q"]) == 1
    assert "an export is an MCAP file" in capsys.readouterr().err
    assert main(["export", str(log), "--chain", str(chain), "--out", str(log), "-q"]) == 1
    assert "would overwrite the log it reads" in capsys.readouterr().err


def test_export_without_findings_still_writes_the_chain(realdata: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """A static target seen once per marker cannot be attributed: the export says why and still writes."""
    chain = tmp_path / "chain.yaml"
    chain.write_text(
        "frames: {camera: raspicam, body: base_link, world: map}\n"
        "topics: {image: /raspicam_node/image/compressed}\n"
        "mounts:\n"
        "  - {parent: map, child: base_link, xyz: [0, 0, 0], quat_xyzw: [0, 0, 0, 1]}\n"
        "  - {parent: base_link, child: raspicam, xyz: [0, 0, 0.5], quat_xyzw: [-0.5, 0.5, -0.5, 0.5]}\n"
        "evidence: {markers: {dictionary: DICT_5X5_1000, size_m: 0.14}, static_target: true}\n")
    out = tmp_path / "annotated.mcap"
    assert main(["export", str(realdata / ARUCO_IMAGES_BAG), "--chain", str(chain), "--out", str(out),
                 "-q"]) == 0
    err = capsys.readouterr().err
    assert "not attributed: static target: no object seen at least 3 times" in err
    assert out.stat().st_size > 0


def test_a_fisheye_calibration_is_exported_as_foxglove_s_kannala_brandt(realdata: Path, tmp_path: Path) -> None:
    """The stairs camera's Kalibr ``equidistant`` model (OpenCV's fisheye) is Foxglove's ``kannala_brandt``, with
    cameras.yaml's four coefficients; "equidistant" is no model Foxglove knows."""
    import yaml

    stairs = realdata / STAIRS
    chain = tmp_path / "chain.yaml"
    chain.write_text(f"""
frames: {{camera: t265_fisheye1_optical_frame, body: basalt_pose_frame, world: world}}
topics: {{detections: /t265/fisheye1/tags, odometry: /vio_node/odom}}
calibration: {{file: {stairs / 'cameras.yaml'}, camera: cam0}}
mounts: [{{parent: basalt_pose_frame, child: t265_fisheye1_optical_frame, xyz: [0.0107, 0, 0], rotvec: [0, 0, 3.14]}}]
evidence: {{tag_size_m: 0.16}}
""")
    out = tmp_path / "annotated.mcap"
    assert main(["export", str(stairs / "tag_detections.bag"), "--chain", str(chain), "--out", str(out),
                 "--no-attribute", "-q"]) == 0
    _, added, _ = _read(out)
    (_, calibration), = added[CALIBRATION_TOPIC]
    cam0 = yaml.safe_load((stairs / "cameras.yaml").read_text())["cam0"]
    assert cam0["distortion_model"] == "equidistant"
    assert calibration.distortion_model == "kannala_brandt"
    np.testing.assert_allclose(list(calibration.D), cam0["distortion_coeffs"])


def test_a_log_without_a_camera_gets_no_annotation_hints(realdata: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """evo's tf_example.bag (odometry only): nothing is annotated, so no line points to annotations or a calibration
    the file does not hold."""
    out = tmp_path / "annotated.mcap"
    assert main(["export", str(realdata / TF_EXAMPLE_BAG), "--out", str(out), "-q"]) == 0
    printed = capsys.readouterr().out
    copied, added, _ = _read(out)
    assert ANNOTATIONS_TOPIC not in added
    assert CALIBRATION_TOPIC not in added
    assert "annotations" not in printed
    assert CALIBRATION_TOPIC not in printed
    assert sum(copied.values()) == 518
