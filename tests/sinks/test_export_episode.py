"""``framechain export`` of a LeRobot episode: a Foxglove MCAP holding its frame tree, joints and video.

Decoded back with the mcap reader and the official Foxglove schemas (foxglove-schemas-protobuf);
the expectations come from the generator's own URDF maths and the dataset's Parquet read with
pyarrow, the video frames from PyAV decoding the dataset's mp4.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

from framechain.cli.main import main
from framechain.sim.lerobot_video import ARM_JOINTS, VideoDatasetSpec, VideoDatasetTruth, generate_video_dataset
from framechain.sim.lerobot_video import write_robot_yaml as write_video_robot_yaml
from framechain.sim.urdf_chain import UrdfChain

FRAMES = 45  # per episode: 1.5 s at 30 fps


def exported(tmp: Path, spec: VideoDatasetSpec, episode: int) -> tuple[VideoDatasetTruth, dict[str, list[Any]]]:
    """Generate, export one episode, and read every message back with the Foxglove schemas."""
    from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    from foxglove_schemas_protobuf.CompressedVideo_pb2 import CompressedVideo
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
    from foxglove_schemas_protobuf.JointStates_pb2 import JointStates
    from foxglove_schemas_protobuf.Log_pb2 import Log
    from mcap.reader import make_reader

    truth = generate_video_dataset(tmp / "dataset", spec)
    robot = write_video_robot_yaml(truth, tmp / "robot.yaml")
    out = tmp / "episode.mcap"
    assert main(["export", str(truth.root), "--episode", str(episode), "--robot", str(robot), "--out", str(out),
                 "-q", "--json"]) == 0
    kinds = {"foxglove.FrameTransforms": FrameTransforms, "foxglove.JointStates": JointStates,
             "foxglove.CompressedVideo": CompressedVideo, "foxglove.CompressedImage": CompressedImage,
             "foxglove.CameraCalibration": CameraCalibration, "foxglove.Log": Log}
    messages: dict[str, list[Any]] = defaultdict(list)
    with out.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            assert schema is not None
            assert schema.encoding == "protobuf"
            decoded = kinds[schema.name]()
            decoded.ParseFromString(message.data)
            messages[channel.topic].append((message.log_time, decoded))
    return truth, messages


def state_rad(truth: VideoDatasetTruth, episode: int) -> np.ndarray:
    """The episode's stored joint state in radians (degrees in the dataset), read with pyarrow alone."""
    files = sorted((truth.root / "data").rglob("*.parquet"))
    table = pq.read_table(files[0], filters=[("episode_index", "=", episode)]).sort_by("index")
    state = np.asarray(table.column("observation.state").combine_chunks().flatten()).reshape(table.num_rows, -1)
    return np.deg2rad(state[:, :len(ARM_JOINTS)])


def video_frames(path: Path, start_s: float, count: int) -> np.ndarray:
    import av

    with av.open(str(path)) as container:
        frames = [f.to_ndarray(format="gray") for f in container.decode(video=0)
                  if f.time is not None and f.time >= start_s - 1e-3]
    return np.stack(frames[:count])


@pytest.fixture(scope="module")
def h264(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, dict[str, list[Any]]]:
    """v3.0, two episodes in one H.264 file without B-frames (key frames every 15): episode 1 exported."""
    spec = VideoDatasetSpec(so101_urdf, seed=41, duration_s=FRAMES / 30, episodes=2, version="v3.0",
                            codec_options=(("bf", "0"), ("g", "15")))
    return exported(tmp_path_factory.mktemp("export_h264"), spec, episode=1)


def test_transforms_are_forward_kinematics(h264: tuple[VideoDatasetTruth, dict[str, list[Any]]]) -> None:
    truth, messages = h264
    tf = messages["/tf"]
    assert len(tf) == FRAMES
    assert [t for t, _ in tf] == sorted(t for t, _ in tf)
    static = {(t.parent_frame_id, t.child_frame_id) for _, m in messages["/tf_static"] for t in m.transforms}
    assert ("gripper_link", "wrist_optical_frame") in static
    # wrist_link -> gripper_link per frame against the generator's own URDF maths on the stored state.
    q = state_rad(truth, 1)
    chain = UrdfChain(truth.spec.urdf)
    joints = dict(zip(ARM_JOINTS, q.T, strict=True))
    expected = np.linalg.inv(chain.root_from_link(joints, "wrist_link")) @ chain.root_from_link(joints, "gripper_link")
    for k, (_, msg) in enumerate(tf):
        (edge,) = [t for t in msg.transforms if (t.parent_frame_id, t.child_frame_id) == ("wrist_link", "gripper_link")]
        xyz = [edge.translation.x, edge.translation.y, edge.translation.z]
        quat = [edge.rotation.x, edge.rotation.y, edge.rotation.z, edge.rotation.w]
        assert np.allclose(xyz, expected[k, :3, 3], atol=1e-9)
        assert np.allclose(Rotation.from_quat(quat).as_matrix(), expected[k, :3, :3], atol=1e-9)


def test_joint_states_are_the_stored_state(h264: tuple[VideoDatasetTruth, dict[str, list[Any]]]) -> None:
    truth, messages = h264
    joints = messages["/joint_states"]
    assert len(joints) == FRAMES
    q = state_rad(truth, 1)
    positions = np.array([[{j.name: j.position for j in m.joints}[name] for name in ARM_JOINTS] for _, m in joints])
    assert np.allclose(positions, q, atol=1e-6)


def test_video_is_h264_access_units_that_decode_to_the_episode(
        h264: tuple[VideoDatasetTruth, dict[str, list[Any]]]) -> None:
    import av

    truth, messages = h264
    video = messages["/wrist/video"]
    assert len(video) == FRAMES
    assert {m.format for _, m in video} == {"h264"}
    assert {m.frame_id for _, m in video} == {"wrist_optical_frame"}
    assert video[0][1].data.startswith((b"\x00\x00\x00\x01", b"\x00\x00\x01"))  # Annex B
    stamps = np.array([m.timestamp.ToNanoseconds() for _, m in video])
    assert np.allclose(stamps, np.arange(FRAMES) / 30 * 1e9, atol=1e5)  # the episode's own time
    decoder = av.CodecContext.create("h264", "r")
    decoded = []
    for _, m in video:  # one access unit per message, as Foxglove decodes them
        decoded += [f.to_ndarray(format="gray") for f in decoder.decode(av.Packet(m.data))]
    decoded += [f.to_ndarray(format="gray") for f in decoder.decode(None)]
    assert len(decoded) == FRAMES
    source = video_frames(truth.root / "videos" / truth.video_key / "chunk-000" / "file-000.mp4", FRAMES / 30, FRAMES)
    assert np.abs(np.stack(decoded).astype(int) - source.astype(int)).max() == 0
    (_, calibration), = messages["/wrist/calibration"]
    assert list(calibration.K) == pytest.approx([180.0, 0.0, 111.5, 0.0, 180.0, 111.5, 0.0, 0.0, 1.0])
    assert (calibration.width, calibration.height, calibration.frame_id) == (224, 224, "wrist_optical_frame")


def test_other_codecs_become_jpeg_images(tmp_path: Path, so101_urdf: Path) -> None:
    import cv2

    spec = VideoDatasetSpec(so101_urdf, seed=42, duration_s=FRAMES / 30, version="v2.1", codec="mpeg4")
    truth, messages = exported(tmp_path, spec, episode=0)
    images = messages["/wrist/image"]
    assert "/wrist/video" not in messages
    assert len(images) == FRAMES
    assert {m.format for _, m in images} == {"jpeg"}
    source = video_frames(truth.root / "videos" / "chunk-000" / truth.video_key / "episode_000000.mp4", 0.0, FRAMES)
    for k in (0, FRAMES // 2, FRAMES - 1):
        grey = cv2.imdecode(np.frombuffer(images[k][1].data, dtype=np.uint8), cv2.IMREAD_GRAYSCALE)
        assert np.abs(grey.astype(int) - source[k].astype(int)).mean() < 3.0


def test_h264_with_b_frames_becomes_jpeg_images(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                so101_urdf: Path) -> None:
    """x264's default (B-frames) cannot be remuxed for Foxglove, which does not reorder: each frame is a JPEG."""
    import av
    import cv2

    spec = VideoDatasetSpec(so101_urdf, seed=43, duration_s=FRAMES / 30, version="v2.1")
    truth, messages = exported(tmp_path, spec, episode=0)
    source = truth.root / "videos" / "chunk-000" / truth.video_key / "episode_000000.mp4"
    with av.open(str(source)) as container:  # the premise: the stored stream has B-frames
        pts = [p.pts for p in container.demux(video=0) if p.pts is not None]
    assert (np.diff(pts) < 0).any()
    assert "/wrist/video" not in messages
    images = messages["/wrist/image"]
    assert len(images) == FRAMES
    frames = video_frames(source, 0.0, FRAMES)
    grey = cv2.imdecode(np.frombuffer(images[FRAMES // 2][1].data, dtype=np.uint8), cv2.IMREAD_GRAYSCALE)
    assert np.abs(grey.astype(int) - frames[FRAMES // 2].astype(int)).mean() < 3.0
    assert "B-frames" in capsys.readouterr().err


def test_an_export_with_nothing_to_write_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from mcap.writer import Writer

    empty = tmp_path / "empty.mcap"
    with empty.open("wb") as f:
        writer = Writer(f)
        writer.start()
        writer.finish()
    out = tmp_path / "out.mcap"
    assert main(["export", str(empty), "--out", str(out), "-q"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert not out.exists()
    assert not list(tmp_path.glob(".*.part"))
