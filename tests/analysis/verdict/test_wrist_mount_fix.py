"""A wrist camera whose recorded mount is off: the error is sized and fixed on the wrist mount edge."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from framechain.analysis.model.estimates import estimate_to_json
from framechain.catalogue import Fault
from framechain.pipeline import attribute_log
from tests.helpers.lerobot_scene import target_world, write_arm_dataset, write_detection_table, write_robot_yaml


def test_wrist_mount_yaw_error_is_four_degrees_on_the_mount_edge(tmp_path: Path) -> None:
    dataset = write_arm_dataset(tmp_path / "ds", version="v3.0", lengths=(90,), camera_delay_s=0.0)
    write_detection_table(tmp_path / "det.parquet", dataset, 0, frames=np.arange(0, 90))
    robot = write_robot_yaml(tmp_path, detections=[{"table": "det.parquet"}], chain={
        "camera": "wrist", "latency_budget_s": 0.02,
        "evidence": {"reference_point": [float(x) for x in target_world()], "static_target": True}})
    calib_path = tmp_path / "calib" / "wrist.yaml"
    calib = yaml.safe_load(calib_path.read_text())
    true_rpy = list(calib["mount"]["rpy"])
    calib["mount"]["rpy"][2] = float(calib["mount"]["rpy"][2] + np.deg2rad(4.0))  # the calibration file is off
    calib_path.write_text(yaml.safe_dump(calib))
    _run, result = attribute_log(tmp_path / "ds", episode=0, robot=robot, bootstrap=0)
    top = result.findings[0]
    assert top.fault == Fault.ROTATION_ERROR
    # A moving camera: the mount error is constant in the mount frame, so it keeps its true size.
    assert abs(estimate_to_json(top.estimate)["angle_deg"] - 4.0) < 0.5
    assert estimate_to_json(top.estimate)["axis_frame"] == "wrist_link"
    assert f"--frame-id {calib['mount']['parent']} --child-frame-id wrist_link" in top.fix
    match = re.search(r'rpy="([^"]+)"', top.fix)
    assert match is not None
    fixed = Rotation.from_euler("xyz", [float(v) for v in match.group(1).split()])
    assert np.rad2deg((fixed * Rotation.from_euler("xyz", true_rpy).inv()).magnitude()) < 0.5
