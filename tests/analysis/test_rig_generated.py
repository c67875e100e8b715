"""Rigs from the independent generator (framechain.sim.rig: its own maths): a fixed arena, a moving rig with
odometry and a moving rig with no pose; as recorded, with one camera's mount turned 5 degrees, and with one
camera's detections stamped one frame late. Checked against the generator's truth, never framechain's output."""

from __future__ import annotations

import re
from dataclasses import replace
from functools import cache

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.analysis.findings import Attribution
from framechain.catalogue import Fault
from framechain.sim import rigid
from framechain.sim.rig import RigScene, RigSpec, generate_rig

#: Small rigs: three cameras, 8 s at 15 Hz (a frame is 66.7 ms).
BASE = RigSpec(cameras=3, duration_s=8.0, rate_hz=15.0, static_tags=12, seed=3)
TURN = (1, 5.0, (0.6, 0.8, 0.0))  # camera 1's recorded mount turned 5 deg about an axis of its own frame
LATE = (2, 1.0)  # camera 2's detections stamped one frame late


@cache
def _attributed(pose: str, fault: str) -> tuple[RigScene, Attribution]:
    spec = replace(BASE, pose=pose, turned=TURN if fault == "turned" else None, late=LATE if fault == "late" else None)
    scene = generate_rig(spec)
    run = pipeline.run(scene.timeline, scene.chain, bootstrap=0)
    return scene, run.attributed()


POSES = ["fixed", "moving", "none"]


@pytest.mark.slow
@pytest.mark.parametrize("pose", POSES)
def test_as_recorded_no_camera_is_a_finding(pose: str) -> None:
    _scene, result = _attributed(pose, "none")
    assert result.metric == "cross_camera"
    assert all(f.share <= 0.10 for f in result.findings), [f.to_json() for f in result.findings]
    assert result.rig is not None
    assert len(result.rig.frames) == 3


@pytest.mark.slow
@pytest.mark.parametrize("pose", POSES)
def test_a_turned_mount_is_found_on_its_camera_with_its_size(pose: str) -> None:
    scene, result = _attributed(pose, "turned")
    top = result.findings[0]
    assert top.fault == Fault.ROTATION_ERROR
    assert top.camera == scene.frame(TURN[0])
    assert top.to_json()["camera"] == scene.frame(TURN[0])
    assert abs(top.estimate.angle_deg - TURN[1]) < 1.0  # type: ignore[union-attr]
    # The fix's corrected mount is the generator's true mount (its own matrices), to within a degree.
    numbers = re.search(r"--roll ([-\d.]+) --pitch ([-\d.]+) --yaw ([-\d.]+)", top.fix)
    assert numbers is not None, top.fix
    rpy = [float(numbers.group(k)) for k in (1, 2, 3)]
    fixed = Rotation.from_euler("xyz", rpy)
    truth = Rotation.from_matrix(scene.true_mounts[scene.frame(TURN[0])][:3, :3])
    assert np.rad2deg((fixed.inv() * truth).magnitude()) < 1.0
    assert f"on camera {scene.frame(TURN[0])}" in result.verdict


@pytest.mark.slow
@pytest.mark.parametrize("pose", POSES)
def test_a_late_camera_is_a_latency_on_that_camera(pose: str) -> None:
    scene, result = _attributed(pose, "late")
    late = [f for f in result.findings if f.fault == Fault.LATENCY]
    assert late, result.verdict
    assert late[0] is result.findings[0]
    assert late[0].camera == scene.frame(LATE[0])
    truth_s = -LATE[1] / BASE.rate_hz  # late by one frame: the pose that explains it is one frame earlier
    assert abs(late[0].estimate.offset_s - truth_s) < 0.15  # type: ignore[union-attr]
    assert abs(late[0].estimate.offset_s - truth_s) < 0.01  # type: ignore[union-attr]  # and well within a frame


@pytest.mark.slow
@pytest.mark.parametrize(("what", "fault", "key"), [("focal", Fault.INTRINSICS, "scale"),
                                                    ("depth", Fault.DEPTH_SCALE, "factor")])
def test_a_camera_s_scale_is_found_on_that_camera(what: str, fault: Fault, key: str) -> None:
    """Camera 2's recorded focal length (or its depths) 8 % off: that camera's fault, x1.08 as recorded."""
    scene = generate_rig(replace(BASE, **{what: (2, 1.08)}))
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    top = result.findings[0]
    assert top.fault == fault
    assert top.camera == scene.frame(2)
    assert top.to_json()["estimate"][key] == pytest.approx(1.08, abs=0.01)


def test_generator_truth_is_its_own() -> None:
    """The generator's recorded mount differs from its truth by exactly the turn it was asked for."""
    scene = generate_rig(replace(BASE, turned=TURN))
    frame = scene.frame(TURN[0])
    delta = rigid.inverse(scene.true_mounts[frame]) @ scene.recorded_mounts[frame]
    assert np.rad2deg(Rotation.from_matrix(delta[:3, :3]).magnitude()) == pytest.approx(5.0, abs=1e-9)
    assert np.allclose(delta[:3, 3], 0.0)
