"""``framechain attribute`` on generated SO-101 episodes as recorded (joint states and a wrist video, no detections).

The episodes and their truth come from :mod:`framechain.sim.lerobot_video` (its own URDF maths and
renderer); robot.yaml declares what a user would: the URDF, the joints, the camera's intrinsics and
its *declared* mount and arm. Every expectation is the generator's truth: the injected video delay
and mount rotation, the arm that carries the camera, a shift of the video's timestamps.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.analysis.model.estimates import LatencyEstimate
from framechain.cli.main import main
from framechain.fleet import run_batch
from framechain.sim.lerobot_video import VideoDatasetSpec, VideoDatasetTruth
from tests.helpers.egomotion_scene import generated, shifted_copy
from tests.helpers.realdata import PANDA_URDF

DURATION_S = 5.0


def attribute(root: Path, robot: Path, out: Path, capsys: pytest.CaptureFixture[str], episode: int = 0
              ) -> dict[str, Any]:
    code = main(["attribute", str(root), "--episode", str(episode), "--robot", str(robot), "--out", str(out),
                 "--format", "json", "--json", "-q"])
    assert code == 0
    result: dict[str, Any] = json.loads(capsys.readouterr().out)
    return result


_ATTRIBUTED: dict[tuple[Path, Path, int], tuple[dict[str, Any], Path]] = {}


def attributed_once(root: Path, robot: Path, factory: pytest.TempPathFactory, capsys: pytest.CaptureFixture[str],
                    episode: int = 0) -> tuple[dict[str, Any], Path]:
    """``attribute``'s JSON for a dataset and robot.yaml no test changes, and its --out folder: run once per
    process, shared by the tests that read it (each gets its own copy of the JSON)."""
    key = (root, robot, episode)
    if key not in _ATTRIBUTED:
        out = factory.mktemp("attributed")
        _ATTRIBUTED[key] = attribute(root, robot, out, capsys, episode), out
    result, out = _ATTRIBUTED[key]
    return copy.deepcopy(result), out


@pytest.fixture(scope="session")
def faulted(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, Path]:
    """v2.1: wrist video 80 ms late, the mount declared 10 degrees off, 10% of the frames resent."""
    return generated(tmp_path_factory, "run_faulted", VideoDatasetSpec(
        so101_urdf, seed=21, duration_s=DURATION_S, version="v2.1", video_delay_s=0.080, mount_error_deg=10.0,
        repeat_share=0.1))


@pytest.fixture(scope="session")
def clean(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, Path]:
    """v3.0, two clean episodes in one mp4."""
    return generated(tmp_path_factory, "run_clean", VideoDatasetSpec(so101_urdf, seed=22, duration_s=DURATION_S,
                                                                     episodes=2, version="v3.0"))


def camera_entry(result: dict[str, Any]) -> dict[str, Any]:
    (entry,) = [e for e in result["camera_motion"] if e["camera"] == "wrist_optical_frame"]
    return entry


def test_late_video_and_a_rotated_mount_are_findings(faulted: tuple[VideoDatasetTruth, Path],
                                                     tmp_path_factory: pytest.TempPathFactory,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    truth, robot = faulted
    result, out = attributed_once(truth.root, robot, tmp_path_factory, capsys)
    assert result["error_m"]["metric"] == "camera_motion"
    found = {f["fault"]: f for f in result["findings"]}
    assert set(found) == {"latency", "rotation_error"}
    latency, mount = found["latency"], found["rotation_error"]
    assert latency["camera"] == mount["camera"] == "wrist_optical_frame"
    assert latency["estimate"]["offset_s"] == pytest.approx(truth.expected_offset_s, abs=0.010)
    low, high = latency["interval"]["offset_s"]
    assert low < latency["estimate"]["offset_s"] < high
    assert mount["estimate"]["angle_deg"] == pytest.approx(truth.spec.mount_error_deg, abs=1.0)
    axis = np.asarray(truth.spec.mount_error_axis) / np.linalg.norm(truth.spec.mount_error_axis)
    assert np.rad2deg(np.arccos(np.clip(np.dot(mount["estimate"]["axis"], axis), -1.0, 1.0))) < 10.0
    measured = Rotation.from_quat(camera_entry(result)["q_link_cam"])
    assert np.rad2deg((measured.inv() * Rotation.from_quat(truth.q_link_cam)).magnitude()) < 1.0
    assert sum(f["share"] for f in result["findings"]) <= 1.0
    assert min(latency["share"], mount["share"]) > 0.2
    assert all(o["observable"] for o in camera_entry(result)["observable"])
    assert (out / "attribution.json").is_file()


def test_the_fixes_as_written_make_the_episode_clean(faulted: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                                     tmp_path_factory: pytest.TempPathFactory,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """The fixes name robot.yaml keys in robot.yaml's own form: applied, nothing is left to find."""
    truth, robot = faulted
    result, _out = attributed_once(truth.root, robot, tmp_path_factory, capsys)
    config = yaml.safe_load(robot.read_text())
    camera = config["cameras"]["wrist"]
    for finding in result["findings"]:
        fix = finding["fix"]
        assert fix.startswith(f"In {robot}, set cameras.wrist.")
        value = yaml.safe_load(fix.split(": ", 1)[1].split(" (")[0])
        if finding["fault"] == "latency":
            camera["timing"] = {"offset_s": value}
        else:
            camera["mount"] = value
    fixed = tmp_path / "robot.yaml"
    fixed.write_text(yaml.safe_dump(config))
    after = attribute(truth.root, fixed, tmp_path / "after", capsys)
    assert all(f["share"] <= 0.10 for f in after["findings"]), after["findings"]
    assert abs(camera_entry(after)["offset_s"]) < 0.005


def test_a_clean_episode_has_no_finding_over_a_tenth(clean: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    truth, robot = clean
    result = attribute(truth.root, robot, tmp_path, capsys, episode=1)
    assert all(f["share"] <= 0.10 for f in result["findings"]), result["findings"]
    entry = camera_entry(result)
    assert entry["link"] == "gripper_link"
    assert abs(entry["offset_s"]) < 0.010
    assert entry["mount_error_deg"] < 1.0
    assert result["verdict"].startswith("No fault beyond noise")


def test_shifted_video_timestamps_move_the_offset(clean: tuple[VideoDatasetTruth, Path], tmp_path: Path) -> None:
    truth, robot = clean
    before = pipeline.run(truth.root, episode=0, robot=robot, bootstrap=0)
    copy = shifted_copy(truth.root, tmp_path / "shifted", 0.100)
    after = pipeline.run(copy, episode=0, robot=robot, bootstrap=0)
    offsets = []
    for made in (before, after):
        assert made.camera_motion is not None
        fit = made.camera_motion.cameras[0].fit
        assert fit is not None
        offsets.append(fit.offset_s)
    # Frames 100 ms later in the file: each row shows the scene 100 ms before its stamp.
    assert offsets[1] - offsets[0] == pytest.approx(-0.100, abs=0.015)
    late = {f.fault.value: f for f in after.findings}
    assert late["latency"].estimate == LatencyEstimate(offsets[1])


def test_a_camera_declared_on_the_other_arm_is_named(tmp_path_factory: pytest.TempPathFactory, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str], so101_urdf: Path) -> None:
    truth, robot = generated(tmp_path_factory, "run_bimanual", VideoDatasetSpec(
        so101_urdf, seed=23, duration_s=DURATION_S, bimanual=True, camera_arm="right_", declared_arm="left_"))
    result = attribute(truth.root, robot, tmp_path, capsys)
    top = result["findings"][0]
    assert top["fault"] == "wrong_camera_frame"
    assert top["camera"] == "wrist_optical_frame"
    assert (top["estimate"]["used"], top["estimate"]["meant"]) == ("left_gripper_link", "right_gripper_link")
    assert "parent: right_gripper_link" in top["fix"]
    assert top["share"] > 0.9


@pytest.fixture(scope="session")
def still(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, Path]:
    """An arm that does not move."""
    return generated(tmp_path_factory, "run_still", VideoDatasetSpec(so101_urdf, seed=24, duration_s=2.0, still=True))


def test_a_still_arm_says_not_observable(still: tuple[VideoDatasetTruth, Path],
                                         tmp_path_factory: pytest.TempPathFactory,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    truth, robot = still
    result, _out = attributed_once(truth.root, robot, tmp_path_factory, capsys)
    assert result["findings"] == []
    entry = camera_entry(result)
    assert [o["observable"] for o in entry["observable"]] == [False, False, False, False]
    # A still arm's frames repeat one another: no frame pair is left to measure, and the reason says why that can be.
    assert "none of its frame pairs could be measured (its frames repeat one another, as a still arm's" in entry[
        "observable"][0]["why"]
    assert "not observable" in result["verdict"] or "no camera turned" in " ".join(result["notes"])


@pytest.mark.parametrize("case", ["axis_flip", "missing_rotation"])
def test_a_flipped_or_bare_mount_is_named_and_fixed(case: str, tmp_path_factory: pytest.TempPathFactory,
                                                     tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                     so101_urdf: Path) -> None:
    """A camera mounted upside down (180 deg about its optical axis), or a mount declared without rotation."""
    spec = VideoDatasetSpec(so101_urdf, seed=25, duration_s=DURATION_S, version="v2.1",
                            mount_error_deg=180.0 if case == "axis_flip" else 0.0, mount_error_axis=(0.0, 0.0, 1.0))
    truth, robot = generated(tmp_path_factory, f"run_{case}", spec)
    if case == "missing_rotation":
        config = yaml.safe_load(robot.read_text())
        config["cameras"]["wrist"]["mount"]["quat_xyzw"] = [0.0, 0.0, 0.0, 1.0]
        robot.write_text(yaml.safe_dump(config))
    result = attribute(truth.root, robot, tmp_path, capsys)
    top = result["findings"][0]
    assert top["fault"] == case
    assert top["share"] > 0.9
    if case == "axis_flip":
        assert top["estimate"]["permutation"] == [[-1, 0, 0], [0, -1, 0], [0, 0, 1]]
    mount = yaml.safe_load(top["fix"].split(": ", 1)[1].split(" (")[0])
    fixed = Rotation.from_euler("xyz", mount["rpy"])
    assert np.rad2deg((fixed.inv() * Rotation.from_quat(truth.q_link_cam)).magnitude()) < 1.0
    assert mount["parent"] == "gripper_link"


def test_a_fixed_camera_is_not_observable_and_not_decoded(faulted: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """A second camera declared fixed in the world (on the same video): its motion says nothing, and says why."""
    truth, robot = faulted
    config = yaml.safe_load(robot.read_text())
    front = {**config["cameras"]["wrist"], "mount": {"parent": "world", "xyz": [0.5, 0.0, 0.4],
                                                     "rpy": [0.0, 0.0, 0.0], "optical": True}}
    config["cameras"]["front"] = front
    config["chain"] = {"camera": "wrist"}
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(config))
    result = attribute(truth.root, tmp_path / "robot.yaml", tmp_path / "out", capsys)
    (entry,) = [e for e in result["camera_motion"] if e["camera"] == "front_optical_frame"]
    assert entry["frames"] == 0  # not decoded
    assert [o["observable"] for o in entry["observable"]] == [False, False, False, False]
    assert "fixed in world" in entry["observable"][0]["why"]
    assert {f["camera"] for f in result["findings"]} == {"wrist_optical_frame"}
    # The bounds say the same, per camera, and the verdict names what the fixed camera cannot show.
    fixed = [b for b in result["bounds"] if b.get("camera") == "front_optical_frame"]
    assert {b["fault"] for b in fixed} == {"latency", "rotation_error", "intrinsics"}
    assert all(not b["observable"] and b["min_detectable"] is None and "fixed in world" in b["why"] for b in fixed)
    assert ("not observable here: camera latency, mount rotation and intrinsics scale on camera front_optical_frame "
            "(camera front_optical_frame is fixed in world") in result["verdict"]


def test_intrinsics_off_by_a_clear_factor_are_a_finding(tmp_path_factory: pytest.TempPathFactory, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str], so101_urdf: Path) -> None:
    truth, robot = generated(tmp_path_factory, "run_focal", VideoDatasetSpec(
        so101_urdf, seed=26, duration_s=DURATION_S, version="v2.1", focal_scale=1.3))
    result = attribute(truth.root, robot, tmp_path, capsys)
    found = {f["fault"]: f for f in result["findings"]}
    assert "intrinsics" in found
    # The focal length used is 1.3 times the true one; the fix gives the true one, and no mount or offset
    # is made up to absorb the scaled rotation.
    assert found["intrinsics"]["estimate"]["scale"] == pytest.approx(1.3, rel=0.05)
    assert found["intrinsics"]["hop"] == "pixel_to_camera"
    fx = float(found["intrinsics"]["fix"].split("cameras.wrist.intrinsics.fx: ")[1].split(" ")[0])
    # Rotation measured in images of a scene at finite depth reads a few percent short (3.1% here).
    assert fx == pytest.approx(truth.intrinsics[0], rel=0.04)
    assert set(found) == {"intrinsics"}


def camera_bounds(result: dict[str, Any], camera: str = "wrist_optical_frame") -> dict[str, dict[str, Any]]:
    return {b["fault"]: b for b in result["bounds"] if b.get("camera") == camera}


def test_a_clean_episode_says_what_its_motion_bounds(clean: tuple[VideoDatasetTruth, Path],
                                                    tmp_path_factory: pytest.TempPathFactory,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """attribution.json's bounds on a run measured by the camera's motion: per camera, in the verdict."""
    truth, robot = clean
    result, _out = attributed_once(truth.root, robot, tmp_path_factory, capsys)
    bounds = camera_bounds(result)
    assert set(bounds) == {"latency", "rotation_error", "intrinsics"}
    assert all(b["observable"] for b in bounds.values())
    latency, mount = bounds["latency"]["min_detectable"]["offset_s"], bounds["rotation_error"]["min_detectable"][
        "angle_deg"]
    assert 0.005 <= latency < 0.015
    assert 2.5 <= mount < 4.5
    assert bounds["intrinsics"]["min_detectable"] == {"scale": 0.1}
    (depth,) = [b for b in result["bounds"] if b["fault"] == "depth_scale"]
    assert not depth["observable"]
    verdict = result["verdict"]
    assert verdict.startswith("No fault beyond noise")
    assert f"No fault above {latency * 1e3:.2g} ms camera latency, " in verdict
    assert "intrinsics scale (set by the noise) on camera wrist_optical_frame" in verdict
    assert "not observable here: depth scale" in verdict
    # The true intrinsics: no note about the focal length.
    assert not [n for n in result["notes"] if "focal length" in n], result["notes"]


@pytest.mark.parametrize("fault", ["latency", "rotation_error"])
def test_a_fault_twice_its_bound_is_found(fault: str, clean: tuple[VideoDatasetTruth, Path],
                                          tmp_path_factory: pytest.TempPathFactory, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str], so101_urdf: Path) -> None:
    """The clean episode's trajectory again, its video late by twice the latency bound, or its mount off by
    twice the mount bound: a finding, within its bound of the generator's truth. (One fault at a time: two
    small ones together share the misfit they remove, and a small latency beside a wrong mount may be none.)"""
    truth, robot = clean
    bound = camera_bounds(attributed_once(truth.root, robot, tmp_path_factory, capsys)[0])[fault]["min_detectable"]
    size = bound["offset_s" if fault == "latency" else "angle_deg"]
    spec = (VideoDatasetSpec(so101_urdf, seed=22, duration_s=DURATION_S, video_delay_s=2 * size)
            if fault == "latency" else
            VideoDatasetSpec(so101_urdf, seed=22, duration_s=DURATION_S, mount_error_deg=2 * size))
    faulted, faulted_robot = generated(tmp_path_factory, f"run_twice_{fault}", spec)
    found = {f["fault"]: f for f in attribute(faulted.root, faulted_robot, tmp_path / "faulted", capsys)["findings"]}
    assert set(found) == {fault}
    if fault == "latency":
        assert found[fault]["estimate"]["offset_s"] == pytest.approx(faulted.expected_offset_s, abs=size)
    else:
        assert found[fault]["estimate"]["angle_deg"] == pytest.approx(2 * size, abs=size)


def test_a_still_arm_bounds_nothing(still: tuple[VideoDatasetTruth, Path], tmp_path_factory: pytest.TempPathFactory,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    truth, robot = still
    result, _out = attributed_once(truth.root, robot, tmp_path_factory, capsys)
    bounds = camera_bounds(result)
    assert set(bounds) == {"latency", "rotation_error", "intrinsics"}
    assert not any(b["observable"] or b["min_detectable"] for b in bounds.values())
    assert result["verdict"].startswith("Nothing could be checked")
    assert "not observable here: camera latency, mount rotation and intrinsics scale on camera wrist_optical_frame (" \
        in result["verdict"]


def test_a_focal_length_a_little_off_is_a_note(clean: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """Declared intrinsics 6% long (not clear enough to fix: a note that gives the implied focal length)."""
    truth, robot = clean
    config = yaml.safe_load(robot.read_text())
    for key in ("fx", "fy"):
        config["cameras"]["wrist"]["intrinsics"][key] *= 1.06
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(config))
    result = attribute(truth.root, tmp_path / "robot.yaml", tmp_path / "out", capsys)
    assert "intrinsics" not in {f["fault"] for f in result["findings"]}
    (note,) = [n for n in result["notes"] if "implies a focal length" in n]
    implied = float(note.split("implies a focal length ")[1].split(" ")[0])
    assert implied == pytest.approx(1 / 1.06, abs=0.03)


def test_motors_mapped_onto_another_robot_are_inconclusive(clean: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str], realdata: Path) -> None:
    """An SO-101's motors mapped onto a Panda's joints: forward kinematics of another robot cannot explain the
    camera's motion, and the verdict says so instead of "no fault" or a confident mount."""
    truth, robot = clean
    panda = realdata / PANDA_URDF
    config = yaml.safe_load(robot.read_text())
    config["urdf"] = str(panda)
    config["joints"] = {"shoulder_pan.pos": "panda_joint1", "shoulder_lift.pos": "panda_joint2",
                        "elbow_flex.pos": "panda_joint4", "wrist_flex.pos": "panda_joint6",
                        "wrist_roll.pos": "panda_joint7"}
    config["hold"] = {"panda_joint3": 0.0, "panda_joint5": 0.0}
    config["cameras"]["wrist"]["mount"]["parent"] = "panda_hand"
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(config))
    result = attribute(truth.root, tmp_path / "robot.yaml", tmp_path / "out", capsys)
    assert not result["findings"]
    assert result["verdict"].startswith("Inconclusive: the model does not explain the motion of camera "
                                        "wrist_optical_frame")
    assert "No fault" not in result["verdict"]
    assert camera_entry(result)["explained"] is False
    # The flags say what the verdict says (a fleet counts the episode inconclusive, not clean).
    assert result["inconclusive"] is True
    (undecided,) = result["undetermined"]
    assert undecided["camera"] == "wrist_optical_frame"
    assert undecided["why"] == camera_entry(result)["unexplained_why"]


def test_a_quarter_turned_mount_brings_no_latency_that_does_not_lower_the_misfit(
        tmp_path_factory: pytest.TempPathFactory, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch, so101_urdf: Path) -> None:
    """On time, mounted 90 degrees off what robot.yaml says: the mount is the finding, and the offset is the truth's
    (0) to a few milliseconds. Tracked with a 15-px window (the 224-px frames' own is 11) a latency of +10 ms is
    fitted beside it, which does not lower the misfit given the mount (a Shapley share at or below zero): a note,
    never a finding with a fix (its fix would put 10 ms of error into a robot.yaml that had none)."""
    from framechain.vision import egomotion

    truth, robot = generated(tmp_path_factory, "run_quarter_turn", VideoDatasetSpec(
        so101_urdf, seed=3, duration_s=6.0, mount_error_deg=90.0))
    own = attribute(truth.root, robot, tmp_path / "own", capsys)
    assert [f["fault"] for f in own["findings"]] == ["rotation_error"]
    assert own["findings"][0]["estimate"]["angle_deg"] == pytest.approx(90.0, abs=3.0)
    assert camera_entry(own)["offset_s"] == pytest.approx(0.0, abs=0.003)
    monkeypatch.setattr(egomotion, "lucas_kanade_window", lambda shape, opts: opts.window_px)
    result = attribute(truth.root, robot, tmp_path / "wide", capsys)
    assert [f["fault"] for f in result["findings"]] == ["rotation_error"]
    assert result["findings"][0]["estimate"]["angle_deg"] == pytest.approx(90.0, abs=3.0)
    assert all(f["share"] > 0 for f in result["findings"])
    (dropped,) = [n for n in result["notes"] if "is no finding: with the other corrections it does not lower" in n]
    assert dropped.startswith("camera wrist_optical_frame: latency at camera_to_body (+")
    assert "Shapley share -" in dropped or "Shapley share +0.00" in dropped
    # Its family bounds nothing: never "no fault above B" beside the +10 ms its fit gave.
    assert "camera latency on camera wrist_optical_frame (its fit (+" in result["verdict"]
    (latency,) = [b for b in result["bounds"] if b["fault"] == "latency"]
    assert latency["observable"] is False


def test_an_episode_too_short_to_resample_says_so(tmp_path_factory: pytest.TempPathFactory, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str], so101_urdf: Path) -> None:
    """1 s, its video 50 ms late, the offset searched +-0.2 s: the frame pairs compared span 0.5 s, one block of the
    bootstrap (every resample the same: intervals of width 0). No estimate, and the reason, not a strong finding."""
    truth, robot = generated(tmp_path_factory, "run_one_second", VideoDatasetSpec(
        so101_urdf, seed=3, duration_s=1.0, video_delay_s=0.05))
    robot.write_text(robot.read_text() + "chain: {evidence: {camera_offset_window_s: 0.2}}\n")
    result = attribute(truth.root, robot, tmp_path, capsys)
    assert result["findings"] == []
    assert result["verdict"].startswith("Nothing could be checked")
    assert "the frame pairs it compares span 0.5" in result["verdict"]
    assert "under the 1.5 s its intervals need" in result["verdict"]
    assert result["inconclusive"] is False
    # A fleet counts it as checking nothing, not as clean.
    batch = run_batch([truth.root], tmp_path / "fleet", robot=robot, jobs=1, bootstrap=0, report_formats=())
    assert [r["status"] for r in batch.records] == ["no_evidence"]


def test_a_camera_declared_on_the_wrist_that_rides_the_gripper_is_named(clean: tuple[VideoDatasetTruth, Path],
                                                                       tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """Declared on wrist_link, the camera rides gripper_link (its child, through wrist_roll): every moving link is a
    candidate, and the finding gives the mount on gripper_link."""
    truth, robot = clean
    config = yaml.safe_load(robot.read_text())
    config["cameras"]["wrist"]["mount"]["parent"] = "wrist_link"
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(config))
    result = attribute(truth.root, tmp_path / "robot.yaml", tmp_path / "out", capsys)
    (found,) = [f for f in result["findings"] if f["fault"] == "wrong_camera_frame"]
    assert found["estimate"] == {"used": "wrist_link", "meant": "gripper_link", "hop": "camera_to_body"}
    assert "mount: {parent: gripper_link" in found["fix"]
    entry = camera_entry(result)
    assert entry["link"] == "gripper_link"
    measured = Rotation.from_quat(entry["q_link_cam"])
    assert np.rad2deg((measured.inv() * Rotation.from_quat(truth.q_link_cam)).magnitude()) < 3.0


def test_an_episode_without_detections_says_what_it_measured(clean: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """No detection is logged, so there is nothing to replay: the counts name the frames and frame pairs each
    camera's motion was measured on (the episode's rows, as the generator wrote them), not "0 total"."""
    truth, robot = clean
    code = main(["attribute", str(truth.root), "--episode", "0", "--robot", str(robot), "--out", str(tmp_path),
                 "--format", "md", "--bootstrap", "0", "-q"])
    assert code == 0
    (line,) = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("observations:")]
    rows = truth.timestamps_s[0].size
    measured = json.loads((tmp_path / "attribution.json").read_text())["camera_motion"]
    (entry,) = [e for e in measured if e["camera"] == "wrist_optical_frame"]
    assert entry["frames"] == rows
    assert entry["pairs"] > 0
    expected = f"camera wrist_optical_frame: {rows} frames, {entry['pairs']} frame pairs"
    assert line.startswith("observations: none logged (no detections)")
    assert expected in line
    assert "0 total" not in line
    report = (tmp_path / "report.md").read_text()
    assert (f"| observations | none logged (no detections); the cameras' own motion measured instead: {expected} of "
            f"{entry['pairs_possible']} possible (") in report
    assert (f"| camera | wrist_optical_frame: declared on gripper_link, {truth.spec.width} px wide, focal "
            f"{truth.declared_focal_px:g} px |") in report
    assert "| stamps | no observations logged, " in report
    # What each hop is attributed is in the rotation rate's unit, as the findings' effects are (it said "0.0 mm").
    assert "| pixel_to_camera | not logged | - | 0 | 0.00 deg/s |" in report


def test_an_offset_window_longer_than_the_episode_is_named(clean: tuple[VideoDatasetTruth, Path], tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """A 10 s offset window on a 5 s episode leaves no frame pair to compare: the
    verdict and the note name the window and its key, never "no camera turned" (the arm turns about 50 deg/s)."""
    truth, robot = clean
    (tmp_path / "robot.yaml").write_text(robot.read_text() + "chain: {evidence: {camera_offset_window_s: 10}}\n")
    result = attribute(truth.root, tmp_path / "robot.yaml", tmp_path / "out", capsys)
    assert result["findings"] == []
    assert "(+-10 s, evidence.camera_offset_window_s) inside both ends" in result["verdict"]
    assert not [n for n in result["notes"] if "turned" in n]


def test_two_cameras_measured_in_forked_processes_give_what_threads_give(
        tmp_path_factory: pytest.TempPathFactory, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch, so101_urdf: Path) -> None:
    import os

    import framechain.analysis.egomotion.run as egomotion_run

    if not egomotion_run.forks():
        pytest.skip("cameras are measured in forked processes on Linux only")
    truth, robot = generated(tmp_path_factory, "run_two_cameras", VideoDatasetSpec(
        so101_urdf, seed=24, duration_s=DURATION_S, bimanual=True, camera_per_arm=True, camera_delays_s=(0.04, 0.07)))
    pids = tmp_path / "pids"
    measure = egomotion_run._measure_camera

    def noting(*args: Any, **kwargs: Any) -> Any:
        with pids.open("a") as f:
            f.write(f"{os.getpid()}\n")
        return measure(*args, **kwargs)

    monkeypatch.setattr(egomotion_run, "_measure_camera", noting)
    monkeypatch.setenv("FRAMECHAIN_CAMERA_THREADS", "2")
    forked = attribute(truth.root, robot, tmp_path / "forked", capsys)
    in_children = set(pids.read_text().split())
    assert len(in_children) == 2
    assert str(os.getpid()) not in in_children
    monkeypatch.setattr(egomotion_run, "forks", lambda: False)
    threaded = attribute(truth.root, robot, tmp_path / "threaded", capsys)
    assert set(pids.read_text().split()) - in_children == {str(os.getpid())}

    def without_times(result: dict[str, Any]) -> list[dict[str, Any]]:
        return [{k: v for k, v in entry.items() if k != "seconds"} for entry in result["camera_motion"]]

    assert len(forked["camera_motion"]) == 2
    assert without_times(forked) == without_times(threaded)  # to the last digit written
    assert forked["findings"] == threaded["findings"]
