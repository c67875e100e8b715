"""A second newcomer's afternoon: what `info` says of a camera frame only the detections name and of the mount
TagSLAM's files give, a chain file beside the log named before it is passed over, a failed log of a batch named,
world equal to body, "did you mean" for every frame, piped output kept whole and ended quietly, a world frame named
world, and other files given as a chain named for what they are."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from framechain.cli.main import main
from framechain.config.chain import ChainConfig
from framechain.config.errors import ChainConfigError
from framechain.sim.logs import write_scene
from framechain.sim.scene import SceneSpec, generate
from tests.helpers.cli_needs import info_needs
from tests.helpers.realdata import FRANKA_BAG, QUAD_RIG_BAG, STAIRS, STAIRS_BAG, TF_EXAMPLE_BAG


def test_info_says_the_mount_is_the_gap_and_gives_tagslam_s_mount(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str],
                                                                 realdata: Path) -> None:
    """The detections' frame is found but in no transform: the mount must connect it, and tagslam.yaml's
    T_body_odom (inverted, as TagSLAM applies it) with cam0's pose in camera_poses.yaml is that mount."""
    bag = realdata / STAIRS_BAG
    chain = tmp_path / "chain.yaml"
    chain.write_text(f"frames: {{camera: t265_fisheye1_optical_frame, body: basalt_pose_frame, world: world}}\n"
                     f"topics: {{detections: /t265/fisheye1/tags, odometry: /vio_node/odom}}\n"
                     f"calibration: {{file: {realdata / STAIRS / 'cameras.yaml'}, camera: cam0}}\n"
                     "evidence: {static_target: true, tag_size_m: 0.16}\n")
    needs = info_needs(capsys, str(bag), "--chain", str(chain))
    assert "no transform of the log names it: the mount must connect it" in needs["camera frame"]["detail"]
    key = needs["mount"]["key"]
    assert "T_body_odom in tagslam.yaml inverted, as TagSLAM applies it" in key
    mount = yaml.safe_load(key.split("  (", 1)[0].removeprefix("mounts: "))[0]
    assert (mount["parent"], mount["child"]) == ("basalt_pose_frame", "t265_fisheye1_optical_frame")
    rig = yaml.safe_load((realdata / STAIRS / "tagslam.yaml").read_text())["bodies"][1]["rig"]["T_body_odom"]
    rotation = Rotation.from_rotvec([rig["rotation"][a] for a in "xyz"]).inv()
    xyz = -rotation.apply([rig["position"][a] for a in "xyz"])
    np.testing.assert_allclose(mount["xyz"], xyz, atol=1e-6)
    np.testing.assert_allclose(Rotation.from_rotvec(mount["rotvec"]).as_matrix(), rotation.as_matrix(), atol=1e-6)
    # The chain says 0.16 m for every tag; tagslam.yaml sizes 100-108 at 0.10 m.
    assert needs["depth"]["key"].startswith("evidence.tag_size_m: {default: 0.16, 100: 0.1")
    # The suggested camera (fisheye2) has no pose in camera_poses.yaml: said so, with the camera that has one.
    alone = info_needs(capsys, str(bag))["mount"]["key"]
    assert "camera_poses.yaml gives no pose of cam1 (the camera of /t265/fisheye2/tags) in the rig" in alone
    assert "cam0: /t265/fisheye1/tags" in alone


def _generated(tmp_path: Path) -> tuple[Path, Path]:
    scene = generate(SceneSpec(seed=2, duration_s=1.0, evidence="hops"))
    log = write_scene(scene, tmp_path / "episode.mcap")
    chain = tmp_path / "chain.yaml"
    chain.write_text(scene.chain.to_yaml())
    return log, chain


def test_attribute_names_a_chain_file_beside_the_log_before_it_suggests_one(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log, chain = _generated(tmp_path)
    assert main(["attribute", str(log), "--out", str(tmp_path / "out"), "--bootstrap", "0"]) == 0
    first = capsys.readouterr().err.splitlines()[0]
    assert first.startswith(f"no --chain given: {chain} lies beside the log but is not used (pass --chain {chain}")


def test_a_batch_names_the_log_that_failed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "broken.mcap").write_bytes(b"\x89MCAP0\r\nnot a log")
    assert main(["batch", str(logs), "--out", str(tmp_path / "fleet"), "-q", "--format", "none"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("1 log: ")  # one log, not "1 logs"
    reason = next(line for line in out if line.startswith("1 nothing_replayed"))
    assert reason.startswith(f"1 nothing_replayed ({logs / 'broken.mcap'}): ")


def test_world_may_equal_body_and_a_default_world_missing_from_the_log_says_so(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], realdata: Path) -> None:
    """"world = body: a fixed rig" can be written; a world left out is the default map, and a log without map
    says so and how to name a body that does not move."""
    fixed = ChainConfig.from_dict({"frames": {"camera": "cam", "body": "rig", "world": "rig"}})
    assert (fixed.frames.body, fixed.frames.world) == ("rig", "rig")
    with pytest.raises(ChainConfigError, match="the camera frame 'rig' must differ from body"):
        ChainConfig.from_dict({"frames": {"camera": "rig", "body": "rig", "world": "map"}})
    bag = realdata / STAIRS_BAG
    chain = tmp_path / "no_world.yaml"
    chain.write_text("frames: {camera: t265_fisheye1_optical_frame, body: basalt_pose_frame}\n"
                     "topics: {detections: /t265/fisheye1/tags, odometry: /vio_node/odom}\n"
                     "mounts: [{parent: basalt_pose_frame, child: t265_fisheye1_optical_frame, xyz: [0, 0, 0], "
                     "rpy: [0, 0, 0]}]\n")
    assert main(["attribute", str(bag), "--chain", str(chain), "--out", str(tmp_path / "out"), "-q"]) == 1
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.endswith("the chain's world frame 'map' is in no transform of the log ('map' is frames.world's "
                         "default: name the log's world frame, or set world equal to body (basalt_pose_frame) for a "
                         "body that does not move)")


def test_info_says_did_you_mean_for_the_body_and_the_world(tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    log, chain = _generated(tmp_path)
    text = chain.read_text()
    for typo, piece, meant in (("base_lnk", "mount", "base_link"), ("mapp", "pose", "map"),
                               ("camera_optcal_frame", "camera frame", "camera_optical_frame")):
        original = {"base_lnk": "base_link", "mapp": "map", "camera_optcal_frame": "camera_optical_frame"}[typo]
        wrong = tmp_path / f"{typo}.yaml"
        wrong.write_text(text.replace(f": {original}\n", f": {typo}\n", 1))
        need = info_needs(capsys, str(log), "--chain", str(wrong))[piece]
        assert f"did you mean '{meant}'" in need["detail"], need
        assert meant in need["key"]


def test_info_piped_keeps_whole_topic_names(capsys: pytest.CaptureFixture[str], realdata: Path) -> None:
    bag = realdata / QUAD_RIG_BAG
    assert main(["info", str(bag), "-q"]) == 0
    out = capsys.readouterr().out
    for topic in ("/quadruple/bottom_left/tags", "/quadruple/bottom_right/tags", "/quadruple/top_right/tags"):
        assert topic in out
    assert "apriltag_msgs/msg/ApriltagArrayStamped" in out


@pytest.mark.parametrize("args", [["tf", "odom", "base_link", "--at", "10.05"], ["info"]])
def test_a_reader_that_leaves_early_ends_the_command_quietly(args: list[str], realdata: Path) -> None:
    """`framechain tf ... | head -1`: the reader stops after a line; the command exits 0 and says nothing."""
    bag = realdata / TF_EXAMPLE_BAG
    command = [sys.executable, "-m", "framechain.cli.main", args[0], str(bag), *args[1:]]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE) as proc:
        assert proc.stdout is not None
        assert proc.stderr is not None
        proc.stdout.readline()
        proc.stdout.close()  # as `head -1` does
        err = proc.stderr.read()
        code = proc.wait(timeout=60)
    assert code == 0, err
    assert err == b""


def test_a_tree_rooted_at_world_suggests_world(capsys: pytest.CaptureFixture[str], realdata: Path) -> None:
    bag = realdata / FRANKA_BAG
    assert main(["info", str(bag), "--chain", "-q"]) == 0
    frames = yaml.safe_load(capsys.readouterr().out)["frames"]
    assert frames == {"world": "world"}  # the camera and body are FILL IN comments: this log has neither


@pytest.mark.parametrize(("name", "said"), [
    ("cameras.yaml", "this is a calibration file (a Kalibr camchain of cam0, cam1, cam2, cam3), not a chain: a chain "
                     "uses it as `calibration: {file: cameras.yaml, camera: cam0}`"),
    ("tagslam.yaml", "this is a TagSLAM configuration, not a chain"),
    ("camera_poses.yaml", "this is a file of camera poses in a rig (cam0), not a chain"),
])
def test_another_file_given_as_a_chain_is_named(name: str, said: str, capsys: pytest.CaptureFixture[str],
                                                realdata: Path, tmp_path: Path) -> None:
    bag = realdata / STAIRS_BAG
    chain = str(realdata / STAIRS / name)
    assert main(["attribute", str(bag), "--chain", chain, "--out", str(tmp_path / "out"), "-q"]) == 1
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert said in line
    assert "unknown keys" not in line
