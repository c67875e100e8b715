"""Wrong frames: "looked up X instead of Y" named from the frames the log really has.

The frame tree here is written by hand (a RealSense-like camera on a mast, a footprint under the
base, map -> odom -> base_link); the fault each swap is called comes from the rotation between the
frames, which the tests state from REP-103 directly, not from framechain's buffer.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.analysis.model.chain import ChainInputs, Perturbation, evaluate
from framechain.analysis.model.estimates import estimate_to_json
from framechain.analysis.model.frame_swaps import (
    body_frame_candidates,
    camera_frame_candidates,
    camera_swap_fault,
    is_signed_permutation,
)
from framechain.catalogue import Fault
from framechain.config.chain import ChainFrames
from framechain.geometry.camera import CameraModel
from framechain.replay import TransformBuffer
from framechain.sim.scene import (
    REALSENSE_OPTICAL_FRAME,
    REALSENSE_OPTICAL_XYZ,
    InjectedFault,
    Scene,
    SceneSpec,
    generate,
)
from framechain.timeline import CameraTable, Timeline, TransformTable

OPTICAL_Q = np.array([-0.5, 0.5, -0.5, 0.5])  # REP-103 camera_link -> optical, q_xyzw
T0 = 1_700_000_000_000_000_000


def test_the_optical_rotation_is_an_axis_permutation() -> None:
    assert is_signed_permutation(OPTICAL_Q)
    assert is_signed_permutation(np.array([1.0, 0.0, 0.0, 0.0]))  # 180 deg about x: y, z flipped
    assert not is_signed_permutation(np.array([0.0, 0.0, 0.0, 1.0]))  # the identity is no flip
    assert not is_signed_permutation(Rotation.from_euler("y", 30, degrees=True).as_quat())
    assert camera_swap_fault(OPTICAL_Q) == Fault.AXIS_FLIP
    assert camera_swap_fault(Rotation.from_euler("y", 30, degrees=True).as_quat()) == Fault.ROTATION_ERROR
    assert camera_swap_fault(np.array([0.0, 0.0, 0.0, 1.0])) == Fault.WRONG_CAMERA_FRAME


def _tree() -> TransformBuffer:
    mount_q = Rotation.from_euler("y", 20, degrees=True).as_quat()
    static = [
        ("base_link", "camera_link", [0.3, 0.0, 1.2], mount_q),
        ("camera_link", "camera_color_optical_frame", [0.0, 0.015, 0.0], OPTICAL_Q),
        ("camera_link", "camera_depth_optical_frame", [0.0, 0.0, 0.0], OPTICAL_Q),
        ("base_link", "base_footprint", [0.0, 0.0, -0.08], [0.0, 0.0, 0.0, 1.0]),
        ("base_link", "wheel_left", [0.0, 0.2, -0.05], [0.0, 0.0, 0.0, 1.0]),
    ]
    tables = [
        TransformTable.from_rows(p, c, [T0], [xyz], [q], is_static=True, source="/tf_static") for p, c, xyz, q in static
    ]
    stamps = T0 + np.arange(0, 3_000_000_000, 100_000_000)
    n = stamps.size
    tables.append(TransformTable.from_rows("map", "odom", stamps, np.tile([0.2, -0.1, 0.0], (n, 1)),
                                           np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), source="/tf"))
    xyz = np.stack([np.linspace(0, 1, n), np.zeros(n), np.zeros(n)], 1)
    yaw = Rotation.from_euler("z", np.linspace(0, 0.5, n)[:, None]).as_quat()
    tables.append(TransformTable.from_rows("odom", "base_link", stamps, xyz, yaw, source="/tf"))
    timeline = Timeline(transforms=TransformTable.concat(tables))
    return TransformBuffer.from_timeline(timeline)


def _inputs(buffer: TransformBuffer) -> ChainInputs:
    frames = ChainFrames(camera="camera_color_optical_frame", body="base_link", world="map")
    stamps = T0 + np.array([500_000_000, 1_000_000_000, 1_500_000_000])
    bc = buffer.lookup("base_link", frames.camera, stamps)
    wb = buffer.lookup("map", "base_link", stamps)
    camera = CameraModel.from_table(
        CameraTable.from_intrinsics(frames.camera, fx=600, fy=600, cx=320, cy=240, width=640, height=480), 0)
    return ChainInputs(
        obs_id=np.arange(3), stamp_ns=stamps, u=np.array([380.0, 300.0, 320.0]), v=np.array([210.0, 250.0, 240.0]),
        depth_m=np.array([2.0, 1.5, 3.0]), camera=camera, t_bc=bc.translation, q_bc=bc.quat_xyzw,
        t_wb=wb.translation, q_wb=wb.quat_xyzw, buffer=buffer, frames=frames, camera_is_dynamic=False,
    )


def test_candidates_are_the_frames_the_log_has_near_the_chain() -> None:
    inputs = _inputs(_tree())
    camera = dict(camera_frame_candidates(inputs))
    # camera_link differs from the optical frame by the REP-103 permutation: an axis flip.
    assert camera["camera_link"] == Fault.AXIS_FLIP
    # The depth optical frame has the colour frame's orientation, 15 mm away: a wrong camera frame.
    assert camera["camera_depth_optical_frame"] == Fault.WRONG_CAMERA_FRAME
    # Never the body side of the chain: those swaps live on body_to_world.
    assert not {"base_link", "odom", "map", "base_footprint"} & set(camera)
    body = body_frame_candidates(inputs)
    assert "base_footprint" in body
    assert not {"map", "odom", "camera_link", "camera_color_optical_frame"} & set(body)


def test_a_camera_swap_drops_the_whole_optical_edge() -> None:
    inputs = _inputs(_tree())
    _, p_body, _ = evaluate(inputs, Perturbation(camera_frame="camera_link"))
    _, p_body_right, _ = evaluate(inputs, Perturbation())
    # Independent maths: the robot used T_base_camera_link alone for optical points.
    mount = Rotation.from_euler("y", 20, degrees=True)
    p_cam = np.array([[0.2, -0.1, 2.0], [-0.05, 0.025, 1.5], [0.0, 0.0, 3.0]])
    mount_xyz, optical_xyz = np.array([0.3, 0.0, 1.2]), np.array([0.0, 0.015, 0.0])
    np.testing.assert_allclose(p_body, mount.apply(p_cam) + mount_xyz, atol=1e-9)
    right = mount.apply(Rotation.from_quat(OPTICAL_Q).apply(p_cam) + optical_xyz) + mount_xyz
    np.testing.assert_allclose(p_body_right, right, atol=1e-9)


def test_a_body_swap_looks_up_the_footprint() -> None:
    inputs = _inputs(_tree())
    _, _, p_world = evaluate(inputs, Perturbation(body_frame="base_footprint"))
    _, _, p_world_right = evaluate(inputs, Perturbation())
    # T_map_footprint = T_map_base T_base_footprint: the points land 8 cm lower (no roll or pitch).
    np.testing.assert_allclose(p_world - p_world_right, np.tile([0.0, 0.0, -0.08], (3, 1)), atol=1e-9)


@pytest.mark.parametrize("frame", ["camera_link", "camera_depth_optical_frame"])
def test_swapped_frames_name_themselves_in_the_estimate(frame: str) -> None:
    from framechain.analysis.model.faults import models_for

    inputs = _inputs(_tree())
    model = next(m for m in models_for(inputs) if m.name == f"frame_swap[camera:{frame}]")
    as_run = model.estimate(np.zeros(0), "as_run", inputs)
    assert (as_run.used, as_run.meant) == (frame, "camera_color_optical_frame")  # type: ignore[union-attr]
    correction = model.estimate(np.zeros(0), "correction", inputs)
    assert (correction.used, correction.meant) == ("camera_color_optical_frame", frame)  # type: ignore[union-attr]


# -- whole scenes from the independent generator ------------------------------------------------
def _swap_scene(evidence: str, fault: InjectedFault, seed: int = 5) -> Scene:
    spec = SceneSpec(seed=seed, duration_s=5.0, evidence=evidence,  # type: ignore[arg-type]
                     optical_frame=REALSENSE_OPTICAL_FRAME, optical_xyz=REALSENSE_OPTICAL_XYZ, faults=(fault,))
    return generate(spec)


@pytest.mark.parametrize("evidence", ["hops", "target"])
def test_the_skipped_optical_edge_is_an_axis_flip_naming_the_frame(evidence: str) -> None:
    scene = _swap_scene(evidence, InjectedFault(Fault.AXIS_FLIP, "robot", {"used": "camera_link"}))
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    top = result.findings[0]
    assert (top.fault, top.hop.value) == (Fault.AXIS_FLIP, "camera_to_body")
    assert estimate_to_json(top.estimate)["used"] == "camera_link"
    assert estimate_to_json(top.estimate)["meant"] == REALSENSE_OPTICAL_FRAME
    assert "camera_color_optical_frame" in top.fix
    assert "not base_link <- camera_link" in top.fix
    assert "rotation_error" not in result.verdict
    assert top.share > 0.95


@pytest.mark.parametrize("evidence", ["hops", "target"])
def test_the_footprint_looked_up_for_the_base(evidence: str) -> None:
    scene = _swap_scene(evidence, InjectedFault(Fault.WRONG_WORLD_FRAME, "robot", {"used": "base_footprint"}))
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    top = result.findings[0]
    assert (top.fault, top.hop.value) == (Fault.WRONG_WORLD_FRAME, "body_to_world")
    assert estimate_to_json(top.estimate)["used"] == "base_footprint"
    assert "map <- base_link" in top.fix


@pytest.mark.parametrize("evidence", ["reference", "static"])
def test_detections_that_name_the_link_are_an_axis_flip_in_the_data(evidence: str) -> None:
    # The recorded detections say camera_link; their pixels are optical: the data skips the optical edge.
    scene = _swap_scene(evidence, InjectedFault(Fault.AXIS_FLIP, "data", {"used": "camera_link"}))
    assert scene.chain.frames.camera == "camera_link"
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    top = result.findings[0]
    assert (top.fault, top.hop.value) == (Fault.AXIS_FLIP, "camera_to_body")
    estimate = estimate_to_json(top.estimate)
    assert (estimate["used"], estimate["meant"]) == ("camera_link", REALSENSE_OPTICAL_FRAME)
    assert f"set the detections' header.frame_id to {REALSENSE_OPTICAL_FRAME}" in top.fix
    assert top.share > 0.9
