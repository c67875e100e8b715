"""No dead ends: `info` says what the chain needs and which key supplies a missing piece; `replay`
and `attribute` with nothing to replay say why in one line; every real log gets a chain that runs
or the list of what it lacks."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from framechain.adapters import write_log
from framechain.cli.main import main
from framechain.config.chain import ChainConfig, ChainFrames, ChainTopics
from framechain.timeline import CameraTable, DepthFrameTable, ObservationTable, Timeline, TransformTable
from tests.helpers.cli_needs import info_needs
from tests.helpers.realdata import LEROBOT_DATASETS, ROS_LOGS, STAIRS

ROOT = Path(__file__).resolve().parents[2]
T0 = 1_700_000_000_000_000_000
OPTICAL_Q = (-0.5, 0.5, -0.5, 0.5)  # camera_link (FLU) -> optical (RDF), REP-103
MOUNT_XYZ = (0.3, 0.0, 0.8)
CHAIN = ChainConfig(
    frames=ChainFrames(camera="camera_optical_frame", body="base_link", world="map"),
    topics=ChainTopics(camera_info="/camera/color/camera_info", detections="/detections"),
)
N_OBS = 12


def _timeline(*, detections: bool = True, camera_info: bool = True, mount: bool = True, late_s: float = 0.0,
              other_camera: bool = False) -> Timeline:
    """map -> base_link moving along x; base_link -> camera_link (the mount) -> camera_optical_frame;
    detections with a depth of their own at pixels inside a 640x480 image."""
    stamps = T0 + np.arange(21, dtype=np.int64) * 50_000_000
    xyz = np.column_stack([0.5 * (stamps - T0) * 1e-9, np.zeros(21), np.zeros(21)])
    tables = [
        TransformTable.from_rows("map", "base_link", stamps, xyz, np.tile([0.0, 0.0, 0.0, 1.0], (21, 1)),
                                 log_time_ns=stamps + 1_000_000, source="/tf"),
        TransformTable.from_rows("camera_link", "camera_optical_frame", [T0], [0.0, 0.015, 0.0], OPTICAL_Q,
                                 is_static=True, source="/tf_static"),
    ]
    if mount:
        tables.append(TransformTable.from_rows("base_link", "camera_link", [T0], MOUNT_XYZ, [0.0, 0.0, 0.0, 1.0],
                                               is_static=True, source="/tf_static"))
    cams = (CameraTable.from_intrinsics("camera_optical_frame", fx=600.0, fy=600.0, cx=320.0, cy=240.0, width=640,
                                        height=480, stamp_ns=T0, source="/camera/color/camera_info")
            if camera_info else CameraTable.empty())
    frame = "camera_optical_frame"
    if other_camera:  # a second camera, with its own CameraInfo, made every detection
        frame = "other_optical_frame"
        tables.append(TransformTable.from_rows("camera_link", frame, [T0], [0.0, -0.05, 0.0], OPTICAL_Q,
                                               is_static=True, source="/tf_static"))
        cams = CameraTable.concat([cams, CameraTable.from_intrinsics(
            frame, fx=600.0, fy=600.0, cx=320.0, cy=240.0, width=640, height=480, stamp_ns=T0,
            source="/other/camera_info")])
    n = N_OBS if detections else 0
    obs_t = stamps[2 : 2 + n] + 10_000_000 + round(late_s * 1e9)
    obs = ObservationTable(
        obs_id=np.arange(n), stamp_ns=obs_t, log_time_ns=obs_t + 20_000_000,
        camera_frame=np.full(n, frame), u=np.linspace(200.0, 440.0, n), v=np.full(n, 250.0),
        depth_m=np.full(n, 2.0), label=np.full(n, "cup"), score=np.ones(n), source=np.full(n, "/detections"),
    )
    return Timeline(transforms=TransformTable.concat(tables), cameras=cams, observations=obs,
                    depth_frames=DepthFrameTable.empty())


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """ROS 1 bags written with the real writer, each lacking one piece."""
    out = tmp_path_factory.mktemp("dead_ends")
    variants = {
        "complete": {}, "no_detections": {"detections": False}, "no_camera_info": {"camera_info": False},
        "no_mount": {"mount": False}, "late": {"late_s": 5.0}, "other_camera": {"other_camera": True},
    }
    return {name: write_log(_timeline(**kw), out / f"{name}.bag", container="rosbag1", chain=CHAIN)
            for name, kw in variants.items()}


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


def test_a_complete_log_is_ready_and_replays(logs: dict[str, Path], tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    needs = info_needs(capsys, str(logs["complete"]))
    assert {p: n["status"] for p, n in needs.items()} == {
        "camera frame": "found", "intrinsics": "found", "detections": "found", "depth": "found",
        "mount": "found", "pose": "found", "evidence": "none"}
    assert "camera_link" in needs["mount"]["detail"]  # the path base_link -> camera_link -> optical
    assert "/tf" in needs["pose"]["detail"]
    assert "static_target" in needs["evidence"]["key"]
    assert main(["replay", str(logs["complete"]), "--save", str(tmp_path / "r.rrd"), "--no-attribute", "--json",
                 "-q"]) == 0
    assert json.loads(capsys.readouterr().out)["counts"]["replayed"] == N_OBS


def test_no_detections_says_so_and_names_the_key(logs: dict[str, Path], tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    log = logs["no_detections"]
    needs = info_needs(capsys, str(log))
    assert needs["detections"]["status"] == "missing"
    assert needs["detections"]["key"].startswith("topics.detections:")
    # replay still writes the frame tree (worth a look), and says why nothing was replayed.
    assert main(["replay", str(log), "--save", str(tmp_path / "r.rrd"), "-q"]) == 0
    line = _one_line(capsys.readouterr().err)
    assert "no detections topic" in line
    assert "`topics.detections: " in line
    assert (tmp_path / "r.rrd").exists()
    assert main(["attribute", str(log), "--out", str(tmp_path / "a"), "-q"]) == 1
    assert "no detections topic" in _one_line(capsys.readouterr().err)


def test_a_topic_the_log_lacks_is_named(logs: dict[str, Path], tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    chain = tmp_path / "chain.yaml"
    raw = CHAIN.to_dict()
    raw["topics"]["detections"] = "/detectionz"
    chain.write_text(yaml.safe_dump(raw))
    needs = info_needs(capsys, str(logs["complete"]), "--chain", str(chain))
    assert needs["detections"]["status"] == "missing"
    assert "/detectionz" in needs["detections"]["detail"]
    assert needs["detections"]["key"] == "topics.detections: /detections"  # the one the log has
    assert main(["attribute", str(logs["complete"]), "--chain", str(chain), "--out", str(tmp_path / "a"), "-q"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "/detectionz" in line
    assert "which the log lacks" in line
    assert "`topics.detections: /detections`" in line


def test_all_rejected_gives_counts_by_reason_and_the_key(logs: dict[str, Path], tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    log = logs["no_camera_info"]
    needs = info_needs(capsys, str(log))
    assert needs["intrinsics"]["status"] == "missing"
    assert needs["intrinsics"]["key"].startswith("calibration: {file:")
    # The rejected detections are still drawn: the recording is written, and one line says why.
    assert main(["replay", str(log), "--save", str(tmp_path / "r.rrd"), "--no-attribute", "-q"]) == 0
    line = _one_line(capsys.readouterr().err)
    assert f"0 of {N_OBS} observations replayed" in line
    assert f"no_camera_info {N_OBS}" in line
    assert "`calibration: {file:" in line
    assert (tmp_path / "r.rrd").is_file()
    assert main(["attribute", str(log), "--out", str(tmp_path / "a"), "-q"]) == 1
    assert f"no_camera_info {N_OBS}" in _one_line(capsys.readouterr().err)


@pytest.mark.parametrize(("name", "reason", "advice"), [
    ("late", "extrapolation", "check the stamps"),
    ("other_camera", "other_camera", "set `frames.camera` to the detections' frame (other_optical_frame)"),
])
def test_rejections_without_a_chain_key_still_say_what_to_do(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, reason: str, advice: str,
) -> None:
    chain = tmp_path / "chain.yaml"
    chain.write_text(CHAIN.to_yaml())
    assert main(["attribute", str(logs[name]), "--chain", str(chain), "--out", str(tmp_path / "a"), "-q"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert f"all rejected: {reason} {N_OBS}" in line
    assert advice in line


def test_a_missing_mount_is_supplied_by_the_chain(logs: dict[str, Path], tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    log = logs["no_mount"]
    needs = info_needs(capsys, str(log))
    assert needs["mount"]["status"] == "missing"
    assert needs["mount"]["key"].startswith("mounts: [{parent: base_link, child: camera_optical_frame")
    assert needs["pose"]["status"] == "found"
    # The key as written in the need, filled in, makes the chain ready.
    raw = CHAIN.to_dict()
    raw["mounts"] = [{"parent": "base_link", "child": "camera_link", "xyz": list(MOUNT_XYZ),
                      "quat_xyzw": [0.0, 0.0, 0.0, 1.0]}]
    chain = tmp_path / "chain.yaml"
    chain.write_text(yaml.safe_dump(raw))
    needs = info_needs(capsys, str(log), "--chain", str(chain))
    assert needs["mount"]["status"] == "found"
    assert "chain.yaml mounts[0]" in needs["mount"]["detail"]
    assert main(["replay", str(log), "--chain", str(chain), "--save", str(tmp_path / "r.rrd"), "--no-attribute",
                 "--json", "-q"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["counts"]["replayed"] == N_OBS


def test_the_suggested_chain_names_only_frames_of_the_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A log with odometry alone: no camera frame, so the suggestion leaves a marked placeholder."""
    stamps = T0 + np.arange(10, dtype=np.int64) * 100_000_000
    tf = TransformTable.from_rows("odom", "base_footprint", stamps, np.zeros((10, 3)),
                                  np.tile([0.0, 0.0, 0.0, 1.0], (10, 1)), source="/tf")
    log = write_log(Timeline(transforms=tf), tmp_path / "odom.bag", container="rosbag1", chain=CHAIN)
    assert main(["info", str(log), "--chain"]) == 0
    text = capsys.readouterr().out
    assert "# camera: FILL IN" in text
    frames = yaml.safe_load(text)["frames"]
    assert frames == {"body": "base_footprint", "world": "odom"}  # nothing invented
    assert "NOT READY" in text
    assert re.search(r"^#\s+topics\.detections: DETECTIONS_TOPIC$", text, flags=re.MULTILINE)


def test_bare_urdf_as_robot_points_at_robot_yaml(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset

    root = write_lerobot_dataset(tmp_path / "ds", [EpisodeData({"observation.state": np.zeros((3, 2), np.float32)})],
                                 features={"observation.state": FeatureSpec("float32", (2,), ["a", "b"])}, fps=10,
                                 version="v3.0")
    urdf = tmp_path / "arm.urdf"
    urdf.write_text('<?xml version="1.0"?>\n<robot name="arm"><link name="base_link"/></robot>\n')
    for command in (["info"], ["replay", "--save", str(tmp_path / "r.rrd")]):
        assert main([command[0], str(root), "--episode", "0", "--robot", str(urdf), *command[1:]]) == 1
        line = _one_line(capsys.readouterr().err)
        assert "a URDF; --robot takes a robot.yaml" in line
        assert "docs/lerobot.md#the-robot-file" in line


# -- every real log --------------------------------------------------------------------------------------
def test_the_real_log_list_is_complete(realdata: Path) -> None:
    found = {str(p.relative_to(realdata)) for p in realdata.glob("*/*") if p.suffix in (".bag", ".mcap")}
    found |= {str(p.parent.relative_to(realdata)) for p in realdata.glob("*/*/metadata.yaml")}
    found |= {str(p.parent.parent.relative_to(realdata)) for p in realdata.glob("*/*/meta/info.json")}
    assert found == set(ROS_LOGS) | set(LEROBOT_DATASETS)


@pytest.mark.parametrize("name", ROS_LOGS)
def test_every_real_log_runs_or_says_what_it_lacks(name: str, realdata: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    log = realdata / name
    if not log.exists():
        pytest.skip(f"{log} not present")
    assert main(["info", str(log), "--json", "-q"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert {n["piece"] for n in info["needs"]} == {"camera frame", "intrinsics", "detections", "depth", "mount",
                                                  "pose", "evidence"}
    missing = [n for n in info["needs"] if n["status"] != "found"]
    for need in missing:
        assert need["key"], need  # each missing piece names the key that supplies it
        assert need["detail"], need
    # Frames of the suggestion are frames of the log (or placeholders).
    frames = {e["parent"] for e in info["edges"]} | {e["child"] for e in info["edges"]}
    frames |= {c["frame"] for c in info["cameras"]}
    # A rig without a pose (tagslam_quad_rig) has its body frame from its calibration files' camera poses.
    frames |= {m[end] for m in info["suggested_chain"].get("mounts", []) for end in ("parent", "child")}
    camera_found = next(n for n in info["needs"] if n["piece"] == "camera frame")["status"] == "found"
    for slot, frame in info["suggested_chain"]["frames"].items():
        if slot not in info["placeholders"]:  # a detections' frame is in no edge until a mount adds one
            assert frame in frames or (slot == "camera" and camera_found), (slot, frame)
    code = main(["replay", str(log), "--save", str(tmp_path / "r.rrd"), "--no-attribute", "-q"])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if info["ready"]:
        assert code == 0, err
        return
    assert code in (0, 1)
    assert "add `" in _one_line(err)  # why nothing replayed, and what to add
    assert main(["attribute", str(log), "--out", str(tmp_path / "a"), "-q"]) == 1
    assert "add `" in _one_line(capsys.readouterr().err)


@pytest.mark.parametrize("name", LEROBOT_DATASETS)
def test_real_lerobot_datasets_say_what_they_need(name: str, realdata: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    root = realdata / name
    if not root.exists():
        pytest.skip(f"{root} not present")
    assert main(["info", str(root), "--json", "-q"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert any("--robot robot.yaml" in n for n in info["notes"])
    assert main(["replay", str(root), "--episode", "0"]) == 1
    assert "--robot robot.yaml" in _one_line(capsys.readouterr().err)


def test_tagslam_needs_name_the_keys_and_the_filled_chain_replays(realdata: Path, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """TagSLAM's stairs log: AprilTag corners and VIO odometry, no /tf, no CameraInfo, cameras.yaml and
    tagslam.yaml beside the bag."""
    folder = realdata / STAIRS
    if not folder.is_dir():
        pytest.skip(f"{folder} not present")
    log = folder / "tag_detections.bag"
    needs = info_needs(capsys, str(log))
    assert needs["detections"]["status"] == "found"
    assert needs["detections"]["detail"].startswith("apriltag_msgs/ApriltagArrayStamped on /")
    topic = needs["detections"]["detail"].split(" on ", 1)[1].split(":", 1)[0]
    cameras = yaml.safe_load((folder / "cameras.yaml").read_text())
    cam = next(name for name, entry in cameras.items() if entry["tagtopic"] == topic)
    assert needs["intrinsics"]["status"] == "missing"
    assert needs["intrinsics"]["key"].startswith(f"calibration: {{file: cameras.yaml, camera: {cam}}}")
    assert needs["depth"]["status"] == "missing"
    # tagslam.yaml's default_tag_size and each tag's own size, with where they were found
    assert needs["depth"]["key"].startswith("evidence.tag_size_m: {default: 0.16, 100: 0.1, ")
    assert needs["depth"]["key"].endswith("(default_tag_size and each tag's size in tagslam.yaml beside the log)")
    assert needs["mount"]["status"] == "missing"
    assert needs["mount"]["key"].startswith("mounts: [{parent: basalt_pose_frame, child: ")
    assert needs["pose"]["status"] == "found"
    assert needs["pose"]["detail"] == "world -> basalt_pose_frame (dynamic, nav_msgs/Odometry on /vio_node/odom)"
    assert needs["evidence"]["key"].startswith("evidence.static_target: true")
    # Every key filled in (an identity mount: the rig frame stands for the body) makes it ready.
    camera_frame = needs["camera frame"]["detail"].split(" ", 1)[0]
    assert camera_frame.endswith("_optical_frame")  # the detections' header.frame_id
    chain = {
        "frames": {"camera": camera_frame, "body": "basalt_pose_frame", "world": "world"},
        "topics": {"detections": topic, "odometry": "/vio_node/odom"},
        "calibration": {"file": str(folder / "cameras.yaml"), "camera": cam},
        "mounts": [{"parent": "basalt_pose_frame", "child": camera_frame, "xyz": [0, 0, 0],
                    "quat_xyzw": [0, 0, 0, 1]}],
        "evidence": {"tag_size_m": 0.16, "static_target": True},
    }
    path = tmp_path / "chain.yaml"
    path.write_text(yaml.safe_dump(chain))
    assert main(["info", str(log), "--chain", str(path), "--json", "-q"]) == 0
    assert json.loads(capsys.readouterr().out)["ready"] is True
    assert main(["replay", str(log), "--chain", str(path), "--save", str(tmp_path / "r.rrd"), "--no-attribute",
                 "--json", "-q"]) == 0
    counts = json.loads(capsys.readouterr().out)["counts"]
    assert counts["replayed"] > 0.9 * counts["total"] > 0
