"""Every number a user writes is checked against what it can physically be: a unit slip is one line
naming the key and the likely unit; a plausible but unusual value is a note the outputs carry."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from framechain.catalogue import Fault
from framechain.cli.main import main
from framechain.config.calibration import load_calibration, read_intrinsics_file
from framechain.config.chain import ChainConfig
from framechain.config.errors import CalibrationError, ChainConfigError, ConfigError, RobotConfigError
from framechain.config.robot import RobotConfig
from tests.helpers.realdata import STAIRS

INTRINSICS = {"fx": 600.0, "fy": 600.0, "cx": 320.0, "cy": 240.0, "width": 640, "height": 480}
MOUNT = {"parent": "link", "xyz": [0.05, 0.0, 0.02], "rpy": [0.0, 0.0, 0.0], "optical": True}


def _mount(**given: Any) -> dict[str, Any]:
    return {"mounts": [{"parent": "base_link", "child": "camera_link", **given}]}


def _error(raw: dict[str, Any]) -> str:
    with pytest.raises(ChainConfigError) as err:
        ChainConfig.from_dict(raw, where="chain.yaml")
    text = str(err.value)
    assert "\n" not in text
    assert text.startswith("chain.yaml: ")
    return text


# -- tag and marker sizes ---------------------------------------------------------------------------
def test_tag_size_of_160_is_millimetres_written_as_metres() -> None:
    text = _error({"evidence": {"tag_size_m": 160}})
    assert "evidence.tag_size_m is 160 m" in text
    assert "millimetres (160 mm is 0.16 m)" in text


@pytest.mark.parametrize(("raw", "key", "slip"), [
    ({"evidence": {"tag_size_m": 0.0005}}, "evidence.tag_size_m is 0.0005 m", "too small for a tag"),
    ({"evidence": {"tag_size_m": 16}}, "evidence.tag_size_m is 16 m", "16 cm is 0.16 m"),
    ({"evidence": {"tag_size_m": {"default": 0.16, 7: 100}}}, "evidence.tag_size_m.7 is 100 m", "millimetres"),
    ({"topics": {"image": "/im"}, "evidence": {"markers": {"dictionary": "DICT_4X4_50", "size_m": 140}}},
     "evidence.markers.size_m is 140 m", "millimetres (140 mm is 0.14 m)"),
])
def test_sizes_out_of_any_tag_range_are_errors(raw: dict[str, Any], key: str, slip: str) -> None:
    text = _error(raw)
    assert key in text
    assert slip in text


def test_unusual_tag_sizes_are_notes() -> None:
    chain = ChainConfig.from_dict({"evidence": {"tag_size_m": {"default": 1.5, 3: 0.006, 4: 0.16}}}, where="c.yaml")
    assert chain.evidence.tag_size_m == {"default": 1.5, "3": 0.006, "4": 0.16}
    assert len(chain.notes) == 2
    assert chain.notes[0].startswith("c.yaml: evidence.tag_size_m.default is 1.5 m: a tag over 1 m is unusual")
    assert chain.notes[1].startswith("c.yaml: evidence.tag_size_m.3 is 0.006 m: a tag under 1 cm is unusual")
    assert ChainConfig.from_dict({"evidence": {"tag_size_m": 0.16}}).notes == ()


# -- rotations in radians that look like degrees ---------------------------------------------------------
def test_rpy_of_180_is_degrees_written_as_radians() -> None:
    text = _error(_mount(rpy=[0, 0, 180]))
    assert "mounts[0].rpy [0, 0, 180] has an angle of 180, beyond 2 pi" in text
    assert "looks like degrees (180 deg is 3.14159 rad)" in text


@pytest.mark.parametrize(("rotation", "key"), [
    ({"rpy": [90, 0, 0]}, "mounts[0].rpy"),
    ({"rpy": [0, -6.5, 0]}, "mounts[0].rpy"),
    ({"rotvec": [0, 0, 90]}, "mounts[0].rotvec"),
    ({"rotvec": [5, 5, 0]}, "mounts[0].rotvec"),  # |rotvec| = 7.07 rad
])
def test_angles_beyond_two_pi_are_errors(rotation: dict[str, Any], key: str) -> None:
    text = _error(_mount(**rotation))
    assert key in text
    assert "beyond 2 pi" in text


def test_angles_beyond_pi_are_notes_and_stay_the_rotation_given() -> None:
    chain = ChainConfig.from_dict(_mount(rpy=[0.0, 0.0, 4.0]), where="c.yaml")
    assert chain.notes == ("c.yaml: mounts[0].rpy [0, 0, 4] has an angle of 4 rad, beyond pi (the same rotation as "
                           "-2.28319)",)
    assert chain.mounts[0].quat_xyzw[2] == pytest.approx(0.9092974268256817)  # sin(2)
    # The tutorial's stairs mount (a rotation vector of 3.139 rad) is neither.
    readme = ChainConfig.from_dict(_mount(xyz=[0.010699, 0.000025, -0.000092],
                                          rotvec=[-0.0135696, 0.0062165, -3.1391944]))
    assert readme.notes == ()


def test_calibration_and_robot_rotations_are_checked_too(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match=r"calibration c: mount\.rpy \[90, 0, 0\] has an angle of 90"):
        load_calibration({"intrinsics": INTRINSICS, "mount": {**MOUNT, "rpy": [90, 0, 0]}}, name="c")
    with pytest.raises(RobotConfigError, match=r"robot: world_from_base\.rotvec \[0, 0, 180\] has a rotation angle"):
        RobotConfig.from_mapping({"urdf": "r.urdf", "default_unit": "rad", "joints": {"a": "a"},
                                  "world_from_base": {"rotvec": [0, 0, 180]}})


# -- translations of a mount ----------------------------------------------------------------------
def test_mount_translations_beyond_a_robot_are_errors_and_far_ones_notes() -> None:
    text = _error(_mount(xyz=[300, 0, 800], rpy=[0, 0, 0]))
    assert "mounts[0].xyz puts the frame 854.4 m from its parent" in text
    assert "millimetres (854.4 mm is 0.8544 m)" in text
    chain = ChainConfig.from_dict(_mount(xyz=[4.0, 0.0, 0.0], rpy=[0, 0, 0]), where="c.yaml")
    assert chain.notes == ("c.yaml: mounts[0].xyz puts the frame 4 m from its parent: unusually far for a mount",)
    with pytest.raises(CalibrationError, match=r"mount\.xyz puts the frame 50 m from its parent"):
        load_calibration({"intrinsics": INTRINSICS, "mount": {**MOUNT, "xyz": [0, 0, 50]}}, name="c")
    with pytest.raises(ChainConfigError, match=r"evidence\.reference_point is 1e\+06 m from the origin"):
        ChainConfig.from_dict({"evidence": {"reference_point": [1e6, 0, 0]}})


# -- intrinsics against the image size -----------------------------------------------------------------
@pytest.mark.parametrize(("change", "expected"), [
    ({"cx": 1280.0}, "intrinsics: cx 1280 is outside the image (width 640 px)"),
    ({"cy": -30.0}, "intrinsics: cy -30 is outside the image (height 480 px)"),
    ({"fx": 0.9, "fy": 0.9, "cx": 320.0}, "intrinsics: fx 0.9 px is too small for an image 640 px wide"),
    ({"fx": 600_000.0, "fy": 600_000.0}, "intrinsics: fx 600000 px is too large for an image 640 px wide"),
])
def test_intrinsics_that_do_not_fit_the_image_are_errors(change: dict[str, float], expected: str) -> None:
    with pytest.raises(CalibrationError) as err:
        load_calibration({"intrinsics": {**INTRINSICS, **change}, "mount": MOUNT}, name="c")
    assert f"calibration c: {expected}" in str(err.value)
    if change.get("fx") == 0.9:
        assert "it looks normalised by the image size" in str(err.value)


def test_intrinsics_files_are_checked_and_non_square_pixels_noted(tmp_path: Path) -> None:
    kalibr = {"cam0": {"camera_model": "pinhole", "intrinsics": [458.6, 457.3, 1367.2, 248.4],
                       "distortion_model": "radtan", "distortion_coeffs": [0.0, 0.0, 0.0, 0.0],
                       "resolution": [752, 480]}}
    (tmp_path / "camchain.yaml").write_text(yaml.safe_dump(kalibr))
    with pytest.raises(CalibrationError, match=r"camchain\.yaml: cam0\.intrinsics: cx 1367\.2 is outside the image"):
        read_intrinsics_file(tmp_path / "camchain.yaml")
    cal = load_calibration({"intrinsics": {**INTRINSICS, "fy": 700.0}, "mount": MOUNT}, name="c")
    assert cal.notes == ("calibration c: intrinsics: fx 600 and fy 700 differ by more than 10 % (pixels are rarely "
                         "that far from square)",)
    assert load_calibration({"intrinsics": INTRINSICS, "mount": MOUNT}, name="c").notes == ()


# -- depth units, clocks, windows and budgets -----------------------------------------------------------
@pytest.mark.parametrize(("scale", "expected"), [
    (1000.0, "depth.scale_m is 1000 metres per unit: it looks like units per metre (give 0.001)"),
    (1e-9, "depth.scale_m is 1e-09 metres per unit, under a micrometre"),
])
def test_depth_units_that_cannot_be_are_errors(scale: float, expected: str) -> None:
    with pytest.raises(CalibrationError) as err:
        load_calibration({"intrinsics": INTRINSICS, "mount": MOUNT, "depth": {"feature": "d", "scale_m": scale}},
                         name="c")
    assert expected in str(err.value)


def test_unusual_depth_units_and_camera_clocks_are_notes() -> None:
    cal = load_calibration({"intrinsics": INTRINSICS, "mount": MOUNT, "depth": {"feature": "d", "scale_m": 0.5},
                            "timing": {"offset_s": 2.5}}, name="c")
    assert cal.notes == ("calibration c: timing.offset_s is 2.5 s: a camera clock over 1 s off is unusual",
                         "calibration c: depth.scale_m is 0.5 metres per unit: unusual (metres 1, millimetres 0.001, "
                         "0.1 mm 0.0001)")
    for usual in (1.0, 0.001, 0.0001, 0.00025):
        assert load_calibration({"intrinsics": INTRINSICS, "mount": MOUNT, "depth": {"feature": "d", "scale_m": usual}},
                                name="c").notes == ()
    with pytest.raises(CalibrationError, match=r"timing\.offset_s is 40000 s, over an hour: it looks like milli"):
        load_calibration({"intrinsics": INTRINSICS, "mount": MOUNT, "timing": {"offset_s": 40000}}, name="c")


@pytest.mark.parametrize(("raw", "expected"), [
    ({"latency_budget_s": 20}, "latency_budget_s is 20 s, too long for a latency budget (over 5 s): it looks like "
                               "milliseconds (20 ms is 0.02 s)"),
    ({"evidence": {"static_window_s": 5000}}, "evidence.static_window_s is 5000 s, too long for a static-target "
                                               "window (over 3600 s): it looks like milliseconds (5000 ms is 5 s)"),
    ({"evidence": {"static_window_s": 0.001}}, "evidence.static_window_s is 0.001 s, shorter than one camera frame"),
    ({"evidence": {"camera_offset_window_s": 500}}, "evidence.camera_offset_window_s is 500 s, too long for a camera "
                                                     "offset search (over 60 s): it looks like milliseconds"),
    ({"evidence": {"camera_offset_window_s": 0.02}}, "evidence.camera_offset_window_s is 0.02 s: the search needs "
                                                      "0.05 s at least"),
    ({"evidence": {"camera_offset_window_s": -1}}, "evidence.camera_offset_window_s must be a positive number"),
])
def test_absurd_budgets_and_windows_are_errors(raw: dict[str, Any], expected: str) -> None:
    assert expected in _error(raw)


def test_long_budgets_and_windows_are_notes() -> None:
    chain = ChainConfig.from_dict({"latency_budget_s": 1.5, "evidence": {"static_window_s": 900,
                                                                         "camera_offset_window_s": 8}}, where="c.yaml")
    assert chain.latency_budget_s == 1.5
    assert chain.evidence.static_window_s == 900.0
    assert chain.evidence.camera_offset_window_s == 8.0
    assert chain.notes == (
        "c.yaml: evidence.static_window_s is 900 s: windows over 10 minutes let odometry drift pose as a fault",
        "c.yaml: evidence.camera_offset_window_s is 8 s: only the frame pairs this far from both ends of an episode "
        "are compared, and the search takes longer",
        "c.yaml: latency_budget_s is 1.5 s: a budget over 1 s lets poses that old through",
    )


def test_joint_offsets_and_holds_in_degrees_are_errors() -> None:
    base = {"urdf": "r.urdf", "default_unit": "deg", "joints": {"a.pos": {"joint": "a", "offset": 90}}}
    with pytest.raises(RobotConfigError, match=r"joints\.a\.pos\.offset is 90, beyond 2 pi: .* looks like degrees"):
        RobotConfig.from_mapping(base)
    with pytest.raises(RobotConfigError, match=r"hold\.b is 180, beyond 2 pi"):
        RobotConfig.from_mapping({**base, "joints": {"a.pos": "a"}, "hold": {"b": 180}})


# -- through the command line --------------------------------------------------------------------------
@pytest.mark.parametrize(("edit", "expected"), [
    (("default: 0.16", "default: 160"), "evidence.tag_size_m.default is 160 m, too large for a tag: it looks like "
                                        "millimetres (160 mm is 0.16 m)"),
    (("tag_size_m: {default: 0.16, 100: 0.10, 101: 0.10, 102: 0.10, 103: 0.10, 104: 0.10, 105: 0.10, 106: 0.10, "
      "107: 0.10}", "tag_size_m: 160"),
     "evidence.tag_size_m is 160 m, too large for a tag: it looks like millimetres (160 mm is 0.16 m)"),
    (("rotvec: [-0.0135696, 0.0062165, -3.1391944]", "rpy: [0, 0, 180]"),
     "mounts[0].rpy [0, 0, 180] has an angle of 180, beyond 2 pi: angles are radians, and this looks like degrees "
     "(180 deg is 3.14159 rad)"),
])
@pytest.mark.parametrize("command", ["info", "attribute"])
def test_unit_slips_through_the_cli_are_one_line_and_exit_1(
    realdata: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], edit: tuple[str, str], expected: str,
    command: str,
) -> None:
    stairs = realdata / STAIRS
    (tmp_path / "cameras.yaml").write_text((stairs / "cameras.yaml").read_text())
    assert edit[0] in STAIRS_CHAIN
    bad = tmp_path / "bad.yaml"
    bad.write_text(STAIRS_CHAIN.replace(edit[0], edit[1]))
    argv = [command, str(stairs / "tag_detections.bag"), "--chain", str(bad)]
    assert main([*argv, "--out", str(tmp_path / "d")] if command == "attribute" else argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err == f"framechain {command}: error: {bad}: {expected}\n"


def test_notes_on_unusual_values_reach_the_attribution(tmp_path: Path) -> None:
    from framechain.sim.logs import write_scene
    from framechain.sim.scene import InjectedFault, SceneSpec, generate

    scene = generate(SceneSpec(seed=11, duration_s=4.0, width=320, height=240, focal_px=300.0, evidence="hops",
                               faults=(InjectedFault(Fault.LATENCY, "robot", {"offset_s": -0.04}),)))
    log = write_scene(scene, tmp_path / "episode.mcap")
    raw = scene.chain.to_dict()
    raw["latency_budget_s"] = 1.5
    chain = tmp_path / "chain.yaml"
    chain.write_text(yaml.safe_dump(raw))
    assert main(["attribute", "-q", str(log), "--chain", str(chain), "--out", str(tmp_path / "out"), "--format", "json",
                 "--bootstrap", "0"]) == 0
    notes = json.loads((tmp_path / "out" / "attribution.json").read_text())["notes"]
    assert f"{chain}: latency_budget_s is 1.5 s: a budget over 1 s lets poses that old through" in notes


def test_every_config_error_is_a_config_error() -> None:
    for error in (ChainConfigError, CalibrationError, RobotConfigError):
        assert issubclass(error, ConfigError)
        assert str(error("file.yaml", "key: what")) == "file.yaml: key: what"


#: The tutorial's chain for the tagslam_stairs bag.
STAIRS_CHAIN = """\
frames: {camera: t265_fisheye1_optical_frame, body: basalt_pose_frame, world: world}
topics: {detections: /t265/fisheye1/tags, odometry: /vio_node/odom}
calibration: {file: cameras.yaml, camera: cam0}
mounts:
  - {parent: basalt_pose_frame, child: t265_fisheye1_optical_frame,
     xyz: [0.010699, 0.000025, -0.000092], rotvec: [-0.0135696, 0.0062165, -3.1391944]}
evidence:
  static_target: true
  tag_size_m: {default: 0.16, 100: 0.10, 101: 0.10, 102: 0.10, 103: 0.10, 104: 0.10, 105: 0.10, 106: 0.10, 107: 0.10}
"""
