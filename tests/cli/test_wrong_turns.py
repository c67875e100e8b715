"""A new user's afternoon without a wrong turn: suggestions that the chain checker accepts, hints that name where
their values come from, typos named as the cause with "did you mean", a folder of logs that is not silently one of
them, one suggested chain everywhere, calibrations of another camera said first, hints that can work, and
camera-frame points that need no intrinsics."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.cli.main import main
from framechain.config.chain import ChainConfig
from tests.helpers.cli_needs import info_needs
from tests.helpers.realdata import QUAD_RIG, QUAD_RIG_BAG, ROS_LOGS, STAIRS, STAIRS_BAG, TF_EXAMPLE_BAG, TURTLESIM_BAG
from tests.helpers.ros1_bags import Ros1Bag

T0 = 1_700_000_000 * 10**9
OPTICAL_Q = (-0.5, 0.5, -0.5, 0.5)  # camera_link (FLU) -> optical (RDF), REP-103


def _one_line(err: str) -> str:
    lines = [line for line in err.strip().splitlines() if line.strip()]
    assert len(lines) == 1, err
    return lines[0]


def _filled(text: str) -> dict[str, object]:
    """The suggested chain with each FILL IN frame given a distinct name, as a user completes it."""
    filled = re.sub(r"^  # (camera|body|world): FILL IN.*$", lambda m: f"  {m.group(1)}: filled_{m.group(1)}",
                    text, flags=re.MULTILINE)
    raw = yaml.safe_load(filled)
    assert isinstance(raw, dict)
    return raw


# -- the suggestion never produces a chain its own checker rejects -------------------------------------
@pytest.mark.parametrize("name", ROS_LOGS)
def test_every_real_suggestion_parses_as_a_chain(name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                 monkeypatch: pytest.MonkeyPatch, realdata: Path) -> None:
    log = realdata / name
    monkeypatch.chdir(tmp_path)  # as a user would: `info LOG --chain > chain.yaml` in a folder of their own
    assert main(["info", str(log), "--chain", "-q"]) == 0
    text = capsys.readouterr().out
    raw = _filled(text)
    chain = ChainConfig.from_dict(raw)  # raises on three frames that are not three different ones
    if chain.has_pose:
        assert len({chain.frames.camera, chain.frames.body, chain.frames.world}) == 3
    else:  # a rig with no pose (tagslam_quad_rig): its cameras agree in the rig's own frame
        assert chain.is_rig
        assert chain.frames.camera != chain.frames.body
    if "FILL IN  # placeholder" not in text:  # complete as suggested: `info --chain FILE` takes it as it is
        path = tmp_path / "chain.yaml"
        path.write_text(text)
        assert main(["info", str(log), "--chain", str(path), "--json", "-q"]) == 0
        frames = json.loads(capsys.readouterr().out)["suggested_chain"]["frames"]
        written = yaml.safe_load(text)
        if "cameras" in written:  # a rig's file names its cameras in `cameras:`, not in frames.camera
            frames.pop("camera")
        assert frames == written["frames"]


def test_a_pose_topic_into_odom_does_not_make_odom_the_body_and_the_world(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Odometry world -> odom (no base frame): odom is the body, so the world is world, not odom again."""
    bag = Ros1Bag()
    for k in range(10):
        bag.odometry("/tagslam/odom", T0 + k * 100_000_000, "world", "odom", (0.1 * k, 0.0, 0.0))
    log = bag.write(tmp_path / "lab.bag")
    assert main(["info", str(log), "--chain", "-q"]) == 0
    text = capsys.readouterr().out
    frames = yaml.safe_load(text)["frames"]
    assert frames == {"body": "odom", "world": "world"}  # the camera is a FILL IN placeholder
    raw = _filled(text)
    chain = tmp_path / "chain.yaml"
    chain.write_text(yaml.safe_dump(raw))
    assert main(["info", str(log), "--chain", str(chain), "--json", "-q"]) == 0


# -- a value taken from a file beside the log names the file -------------------------------------------
def test_hints_from_files_beside_the_log_name_the_file(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                       realdata: Path) -> None:
    bag = realdata / STAIRS_BAG
    needs = info_needs(capsys, str(bag))
    # tagslam.yaml's default and the tags it sizes otherwise (100-108 are 0.10 m)
    assert needs["depth"]["key"] == ("evidence.tag_size_m: {default: 0.16, 100: 0.1, 101: 0.1, 102: 0.1, 103: 0.1, "
                                     "104: 0.1, 105: 0.1, 106: 0.1, 107: 0.1, 108: 0.1}  (default_tag_size and each "
                                     "tag's size in tagslam.yaml beside the log)")
    assert needs["intrinsics"]["key"] == ("calibration: {file: cameras.yaml, camera: cam1}  (cameras.yaml beside the "
                                          "log: cam1's tagtopic is /t265/fisheye2/tags)")
    # Beside a chain file: its tag size, named as that file's, and how to use the whole chain.
    beside = tmp_path / "beside"
    beside.mkdir()
    (beside / "tag_detections.bag").symlink_to(bag)
    (beside / "chain.yaml").write_text("evidence: {tag_size_m: 0.15}\n")
    depth = info_needs(capsys, str(beside / "tag_detections.bag"))["depth"]
    assert depth["key"] == ("evidence.tag_size_m: 0.15  (tag_size_m in chain.yaml beside the log: `--chain chain.yaml` "
                            "uses that chain)")
    # Without a file, the placeholder says what it stands for.
    alone = tmp_path / "alone"
    alone.mkdir()
    (alone / "tag_detections.bag").symlink_to(bag)
    needs = info_needs(capsys, str(alone / "tag_detections.bag"))
    assert needs["depth"]["key"] == "evidence.tag_size_m: TAG_EDGE_M  (the printed tags' edge in metres)"
    assert needs["intrinsics"]["key"].startswith("calibration: {file: CAMERAS.yaml, camera: NAME}")


# -- a typo is named as the cause, with what it may have meant -----------------------------------------
def _stairs_chain(tmp_path: Path, realdata: Path, **topics: str) -> Path:
    chain = {
        "frames": {"camera": "t265_fisheye1_optical_frame", "body": "basalt_pose_frame", "world": "world"},
        "topics": {"detections": "/t265/fisheye1/tags", "odometry": "/vio_node/odom", **topics},
        "calibration": {"file": str(realdata / STAIRS / "cameras.yaml"), "camera": "cam0"},
        "mounts": [{"parent": "basalt_pose_frame", "child": "t265_fisheye1_optical_frame", "xyz": [0.0107, 0.0, 0.0],
                    "rotvec": [-0.0135696, 0.0062165, -3.1391944]}],
        "evidence": {"static_target": True, "tag_size_m": 0.16},
    }
    path = tmp_path / "chain.yaml"
    path.write_text(yaml.safe_dump(chain))
    return path


def test_a_misspelt_pose_topic_is_the_cause_not_the_world_frame(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str],
                                                                realdata: Path) -> None:
    bag = realdata / STAIRS_BAG
    chain = _stairs_chain(tmp_path, realdata, odometry="/vio_node/odm")
    assert main(["attribute", str(bag), "--chain", str(chain), "--out", str(tmp_path / "o"), "-q"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "topics.odometry /vio_node/odm is not in the log; did you mean '/vio_node/odom'?" in line
    assert line.index("topics.odometry") < line.index("world frame 'world'")  # the cause first


def test_a_misspelt_detections_topic_says_did_you_mean(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                       realdata: Path) -> None:
    bag = realdata / STAIRS_BAG
    chain = _stairs_chain(tmp_path, realdata, detections="/t265/fisheye1/tag")
    needs = info_needs(capsys, str(bag), "--chain", str(chain))
    assert needs["detections"]["status"] == "missing"
    assert "did you mean '/t265/fisheye1/tags'" in needs["detections"]["detail"]
    assert needs["detections"]["key"] == "topics.detections: /t265/fisheye1/tags"
    assert needs["depth"]["status"] == "found"  # the tag size is there; the topic is what is wrong
    assert main(["attribute", str(bag), "--chain", str(chain), "--out", str(tmp_path / "o"), "-q"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "did you mean '/t265/fisheye1/tags'" in line
    assert line.count("did you mean") == 1  # said once


def test_tf_with_a_frame_the_log_lacks(capsys: pytest.CaptureFixture[str], realdata: Path) -> None:
    log = realdata / TF_EXAMPLE_BAG
    assert main(["tf", str(log), "vision", "odm"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert "frame 'vision' does not exist in the log (no transform names it)" in line
    assert "frame 'odm' does not exist in the log (no transform names it); did you mean 'odom'?" in line
    assert "mounts: or urdf: need --chain" in line


# -- a folder of several logs is not silently one of them ----------------------------------------------
def test_a_folder_of_logs_lists_them_and_points_to_batch(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                         realdata: Path) -> None:
    folder = tmp_path / "logs"
    folder.mkdir()
    (folder / "tf_example.bag").symlink_to(realdata / TF_EXAMPLE_BAG)
    (folder / "example.bag").symlink_to(realdata / TURTLESIM_BAG)
    for command in (["info"], ["attribute", "--out", str(tmp_path / "o")]):
        assert main([command[0], str(folder), *command[1:], "-q"]) == 1
        line = _one_line(capsys.readouterr().err)
        assert "a folder of 2 logs (example.bag, tf_example.bag)" in line
        assert f"framechain batch {folder} --out DIR" in line


def test_a_folder_with_one_log_and_an_export_reads_the_log(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                           realdata: Path) -> None:
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "tf_example.bag").symlink_to(realdata / TF_EXAMPLE_BAG)
    export = folder / "annotated.mcap"
    assert main(["export", str(folder / "tf_example.bag"), "--out", str(export), "--no-attribute", "-q"]) == 0
    capsys.readouterr()
    assert main(["info", str(folder), "--json", "-q"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["path"] == str(folder / "tf_example.bag")
    assert info["format"] == "rosbag1"
    assert any(n.startswith(f"{export} skipped: written by framechain") for n in info["notes"])


# -- one suggestion everywhere --------------------------------------------------------------------------
def test_replay_and_export_show_the_suggestion_with_its_placeholders(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str],
                                                                    realdata: Path) -> None:
    log = realdata / TF_EXAMPLE_BAG  # odometry only: no camera frame
    assert main(["replay", str(log), "--save", str(tmp_path / "r.rrd"), "--no-attribute"]) == 0
    captured = capsys.readouterr()
    assert "chain         CAMERA_OPTICAL_FRAME (FILL IN) -> base_link -> odom (suggested;" in captured.out
    assert "camera_optical_frame" not in captured.out  # no invented frame
    incomplete = next(line for line in captured.out.splitlines() if "the suggested chain is incomplete" in line)
    assert "this log lacks camera frame, intrinsics, detections, depth, mount" in incomplete
    # The chain printed on stderr is the one `info --chain` writes, unwrapped: it parses to the same frames.
    printed = captured.err.split("(edit it and pass --chain):\n", 1)[1]
    assert main(["info", str(log), "--chain", "-q"]) == 0
    written = capsys.readouterr().out
    assert yaml.safe_load(printed) == yaml.safe_load(written)
    assert all(line.startswith(("#", " ", "frames:", "topics:", "latency_budget_s:", "evidence:"))
               for line in printed.splitlines() if line)
    assert main(["replay", str(log), "--save", str(tmp_path / "r.rrd"), "--no-attribute", "--json", "-q"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["frames"]["camera"] == "CAMERA_OPTICAL_FRAME"
    assert report["placeholders"] == ["camera"]
    assert report["chain_incomplete"] == incomplete.removeprefix("note").strip()
    assert main(["export", str(log), "--out", str(tmp_path / "a.mcap"), "--no-attribute"]) == 0
    out = capsys.readouterr().out
    assert "chain         CAMERA_OPTICAL_FRAME (FILL IN) -> base_link -> odom (suggested)" in out
    assert incomplete in out


# -- a calibration of another camera is said first ------------------------------------------------------
def test_a_calibration_of_another_topic_is_said_before_the_findings(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str],
                                                                    realdata: Path) -> None:
    bag = realdata / STAIRS_BAG
    raw = yaml.safe_load(_stairs_chain(tmp_path, realdata).read_text())
    raw["calibration"]["camera"] = "cam1"  # the right fisheye's, for the left fisheye's tags
    chain = tmp_path / "chain.yaml"
    chain.write_text(yaml.safe_dump(raw))
    out = tmp_path / "o"
    assert main(["attribute", str(bag), "--chain", str(chain), "--out", str(out), "--bootstrap", "0",
                 "--format", "json"]) == 0
    captured = capsys.readouterr()
    warning = ("calibration cameras.yaml [cam1]: its tagtopic is /t265/fisheye2/tags, but the chain's "
               "topics.detections is /t265/fisheye1/tags: these are another camera's intrinsics: use camera: cam0 "
               "(cameras.yaml gives /t265/fisheye1/tags to cam0)")
    # First: before the fits (only the reader's progress may come before it in a slow run).
    first = next(line for line in captured.err.splitlines() if not line.startswith("framechain: reading "))
    assert first == f"framechain attribute: warning: {warning}"
    assert json.loads((out / "attribution.json").read_text())["notes"][0] == warning
    assert pipeline.run(bag, chain, attribute=False).warnings == (warning,)  # the run holds it for any sink
    raw["calibration"]["camera"] = "cam0"
    chain.write_text(yaml.safe_dump(raw))
    assert main(["info", str(bag), "--chain", str(chain), "--json", "-q"]) == 0
    assert not any("calibration cameras.yaml" in n for n in json.loads(capsys.readouterr().out)["notes"])


def test_detections_stamped_with_another_camera_s_frame_are_noted(capsys: pytest.CaptureFixture[str],
                                                                  realdata: Path) -> None:
    """TagSLAM's quad rig: three of the four tag topics carry another camera's header.frame_id."""
    bag = realdata / QUAD_RIG_BAG
    cameras = yaml.safe_load((realdata / QUAD_RIG / "cameras.yaml").read_text())
    tagtopics = {entry["tagtopic"] for entry in cameras.values()}
    assert main(["info", str(bag), "--json", "-q"]) == 0
    notes = [n for n in json.loads(capsys.readouterr().out)["notes"] if "header.frame_id" in n]
    stamped = {n.split(":", 1)[0].removeprefix("topic ") for n in notes}
    assert stamped == tagtopics - {"/quadruple/bottom_right/tags"}
    assert ("topic /quadruple/top_right/tags: its detections' header.frame_id is 'quadruple/bottom_left', the camera "
            "of another topic (/quadruple/bottom_left/tags)") in " ".join(notes)


# -- a hint that can work ---------------------------------------------------------------------------------
def test_the_static_target_hint_says_what_can_help() -> None:
    from framechain.analysis.evidence.static import _what_can_help

    labels = np.array(["1", "2", "1", "2", "1"])
    one_image = np.full(5, T0)
    usable = np.ones(5, dtype=bool)
    assert "a longer evidence.static_window_s cannot add sightings" in _what_can_help(labels, one_image, usable, 3)
    spread = T0 + np.arange(5) * 4 * 10**9  # five images over 16 s; label 1 three times over the whole log
    assert _what_can_help(labels, spread, usable, 3).startswith("lengthen evidence.static_window_s (the whole log, "
                                                                "16 s, holds 3 sightings of label 1)")
    assert "cannot help: record more images" in _what_can_help(labels, spread, usable, 4)


# -- marker poses in the camera frame need no intrinsics --------------------------------------------------
def test_fiducial_transforms_replay_without_intrinsics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """fiducial_msgs/FiducialTransformArray (the markers' poses in the camera frame) and no CameraInfo: the
    needs agree with the chain (intrinsics not needed, detections found) and every marker is replayed to the
    world point scipy composes independently."""
    mount_xyz, markers = (0.3, 0.0, 0.8), {3: (0.1, -0.05, 1.5), 7: (-0.2, 0.1, 2.0)}
    bag = Ros1Bag()
    bag.tf("/tf_static", T0, "base_link", "cam_optical", mount_xyz, OPTICAL_Q)
    for k in range(21):
        bag.odometry("/odom", T0 + k * 50_000_000, "map", "base_link", (0.025 * k, 0.0, 0.0))
    stamps = T0 + np.arange(2, 18) * 50_000_000  # on the odometry's samples: no interpolation to model
    for t in stamps.tolist():
        bag.fiducial_transforms("/fiducial_transforms", t, "cam_optical", markers)
    log = bag.write(tmp_path / "fiducials.bag")
    chain = tmp_path / "chain.yaml"
    chain.write_text(yaml.safe_dump({"frames": {"camera": "cam_optical", "body": "base_link", "world": "map"},
                                     "topics": {"detections": "/fiducial_transforms", "odometry": "/odom"}}))
    assert main(["info", str(log), "--chain", str(chain), "--json", "-q"]) == 0
    info = json.loads(capsys.readouterr().out)
    needs = {n["piece"]: n for n in info["needs"]}
    assert info["ready"] is True
    assert needs["intrinsics"]["detail"].startswith("not needed: the detections of /fiducial_transforms are 3D points")
    assert needs["detections"]["status"] == "found"
    assert "32 detections" in needs["detections"]["detail"]
    run = pipeline.run(log, chain, attribute=False)
    assert run.replay.counts()["replayed"] == 32
    obs = run.replay.observations
    points = np.array([markers[int(label)] for label in obs.label.tolist()])
    body_x = 0.025 * (obs.stamp_ns - T0) / 50_000_000
    expected = Rotation.from_quat(OPTICAL_Q).apply(points) + np.array(mount_xyz) + np.column_stack(
        [body_x, np.zeros_like(body_x), np.zeros_like(body_x)])
    assert np.abs(run.replay.p_world - expected).max() < 1e-9
    # The viewers draw no pixels for them (no image to draw on), and nothing fails on the camera-less model.
    assert main(["replay", str(log), "--chain", str(chain), "--save", str(tmp_path / "r.rrd"), "--no-attribute",
                 "--json", "-q"]) == 0
    entities = json.loads(capsys.readouterr().out)["entities"]
    assert "/points/recomputed/world" in entities
    assert not any(e.startswith("/camera/") for e in entities)
    assert main(["export", str(log), "--chain", str(chain), "--out", str(tmp_path / "a.mcap"), "--no-attribute",
                 "--json", "-q"]) == 0
    assert "/framechain/annotations" not in json.loads(capsys.readouterr().out)["added"]
