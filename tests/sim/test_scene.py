"""Generated scenes against independent maths: pytransform3d's frame graph, scipy, hand-worked values.

A clean scene's detections must land on the object through the recorded chain (within the noise),
and each real-form fault must change exactly what it claims to change.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import pytransform3d.rotations as pr
import pytransform3d.transformations as pt
from pytransform3d.transform_manager import NumpyTimeseriesTransform, StaticTransform, TemporalTransformManager
from scipy.spatial.transform import Rotation

from framechain.catalogue import Fault
from framechain.sim.scene import (
    REALSENSE_OPTICAL_FRAME,
    REALSENSE_OPTICAL_XYZ,
    START_NS,
    InjectedFault,
    Scene,
    SceneError,
    SceneSpec,
    generate,
)
from framechain.timeline import PointRole

REALSENSE = {"optical_frame": REALSENSE_OPTICAL_FRAME, "optical_xyz": REALSENSE_OPTICAL_XYZ}
REP103_XYZW = [-0.5, 0.5, -0.5, 0.5]  # camera_link (x fwd, y left, z up) -> optical (x right, y down, z fwd)


def _scene(*faults: InjectedFault, evidence: str = "hops", **spec: object) -> Scene:
    options: dict[str, object] = {"seed": 4, "duration_s": 3.0, "evidence": evidence, **REALSENSE, **spec}
    return generate(SceneSpec(faults=faults, **options))  # type: ignore[arg-type]


def _graph(scene: Scene) -> TemporalTransformManager:
    """The recorded /tf and /tf_static as pytransform3d's temporal frame graph (ScLERP between samples)."""
    tf = scene.timeline.transforms
    graph = TemporalTransformManager()
    for parent, child in sorted({(str(p), str(c)) for p, c in zip(tf.parent, tf.child, strict=True)}):
        rows = np.flatnonzero((tf.parent == parent) & (tf.child == child))
        pqs = np.c_[tf.translation[rows], [pr.quaternion_wxyz_from_xyzw(q) for q in tf.quat_xyzw[rows]]]
        if tf.is_static[rows[0]]:
            graph.add_transform(child, parent, StaticTransform(pt.transform_from_pq(pqs[0])))
        else:
            seconds = (tf.stamp_ns[rows] - START_NS) * 1e-9
            graph.add_transform(child, parent, NumpyTimeseriesTransform(seconds, pqs))
    return graph


def _static(scene: Scene, parent: str, child: str) -> np.ndarray:
    tf = scene.timeline.transforms
    row = np.flatnonzero((tf.parent == parent) & (tf.child == child) & tf.is_static)
    assert row.size == 1, (parent, child)
    pq = np.r_[tf.translation[row[0]], pr.quaternion_wxyz_from_xyzw(tf.quat_xyzw[row[0]])]
    return np.asarray(pt.transform_from_pq(pq))


def _points(scene: Scene, role: PointRole) -> np.ndarray:
    points = scene.timeline.points
    return np.asarray(points.xyz[points.role == role.value])


def _apply(transforms: np.ndarray, points: np.ndarray) -> np.ndarray:
    return np.array([pt.transform(m, np.r_[p, 1.0])[:3] for m, p in zip(transforms, points, strict=True)])


def _world_from(scene: Scene, frame: str, stamp_ns: np.ndarray, world: str = "map") -> np.ndarray:
    graph = _graph(scene)
    return np.array([graph.get_transform_at_time(frame, world, (s - START_NS) * 1e-9) for s in stamp_ns])


def _recorded_world_points(scene: Scene) -> np.ndarray:
    """Each detection through the recorded camera_info and /tf (pytransform3d, not the generator)."""
    obs, K = scene.timeline.observations, scene.timeline.cameras.K[0]
    p_cam = np.c_[(obs.u - K[0, 2]) / K[0, 0] * obs.depth_m, (obs.v - K[1, 2]) / K[1, 1] * obs.depth_m, obs.depth_m]
    return _apply(_world_from(scene, scene.chain.frames.camera, obs.stamp_ns), p_cam)


def test_clean_scene_lands_on_the_object_through_the_recorded_chain() -> None:
    noiseless = _scene(pixel_noise_px=0.0, depth_noise_rel=0.0)
    error = np.linalg.norm(_recorded_world_points(noiseless) - noiseless.object_world, axis=1)
    assert noiseless.timeline.observations.stamp_ns.size > 60
    assert error.max() < 1e-3  # depth rounded to the millimetre, ScLERP vs lerp+slerp ~1e-5 m
    noisy = _scene()
    error = np.linalg.norm(_recorded_world_points(noisy) - noisy.object_world, axis=1)
    # 0.5 px at ~2.5 m is ~2 mm; 0.3 % depth noise is ~8 mm.
    assert np.median(error) < 0.01
    assert error.max() < 0.05
    # The robot was right: what it acted on is the recorded chain's answer, and so is its body point.
    np.testing.assert_allclose(noisy.robot_world, _recorded_world_points(noisy), atol=1e-4)


def test_static_tree_is_a_realsense_on_a_pitched_mount() -> None:
    scene = _scene()
    mount = _static(scene, "base_link", "camera_link")
    np.testing.assert_allclose(mount[:3, 3], [0.30, 0.0, 1.20])
    np.testing.assert_allclose(mount[:3, :3], pr.active_matrix_from_angle(1, np.deg2rad(30.0)), atol=1e-12)
    optical = _static(scene, "camera_link", REALSENSE_OPTICAL_FRAME)
    np.testing.assert_allclose(optical[:3, 3], [0.0, 0.015, 0.0])
    # REP-103: the optical z (forward) is camera_link x, optical x (right) is -y, optical y (down) is -z.
    np.testing.assert_allclose(optical[:3, :3], [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-12)
    assert scene.chain.frames.camera == REALSENSE_OPTICAL_FRAME
    assert set(scene.timeline.observations.camera_frame) == {REALSENSE_OPTICAL_FRAME}


def test_optical_edge_dropped_uses_the_mount_alone() -> None:
    scene = _scene(InjectedFault(Fault.AXIS_FLIP, "robot", {"used": "camera_link"}))
    p_cam, p_body = _points(scene, PointRole.HOP_CAMERA), _points(scene, PointRole.HOP_BODY)
    r_mount = Rotation.from_euler("y", 30.0, degrees=True).as_matrix()
    np.testing.assert_allclose(p_body, p_cam @ r_mount.T + [0.30, 0.0, 1.20], atol=1e-12)
    # The camera points themselves are right: the recorded intrinsics of the recorded pixels.
    clean = _scene()
    np.testing.assert_allclose(p_cam, _points(clean, PointRole.HOP_CAMERA), atol=1e-12)
    (expected,) = scene.expected_findings
    assert (expected.fault, expected.hop, expected.estimate) == ("axis_flip", "camera_to_body", {"used": "camera_link"})
    assert expected.names("axis_flip", "camera_to_body", {"used": "camera_link"})
    assert not expected.names("rotation_error", "camera_to_body", {"angle_deg": 120.0})
    assert not expected.names("axis_flip", "camera_to_body", {"permutation": [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]})


def test_depth_optical_frame_for_the_colour_one_shifts_camera_points_by_the_imager_offset() -> None:
    scene, clean = _scene(InjectedFault(Fault.WRONG_CAMERA_FRAME, "robot")), _scene()
    np.testing.assert_allclose(_static(scene, "camera_link", "camera_depth_optical_frame"),
                               pt.transform_from(np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]]), [0, 0, 0]), atol=1e-12)
    # The colour imager sits 15 mm along camera_link's y; dropping it moves every body point by -15 mm
    # along the mount's y (the pitch is about y, so that is base_link's y too).
    shift = _points(scene, PointRole.HOP_BODY) - _points(clean, PointRole.HOP_BODY)
    np.testing.assert_allclose(shift, np.tile([0.0, -0.015, 0.0], (len(shift), 1)), atol=1e-12)
    assert scene.expected_findings[0].estimate == {"used": "camera_depth_optical_frame"}
    with pytest.raises(SceneError, match="optical_xyz"):
        _scene(InjectedFault(Fault.WRONG_CAMERA_FRAME, "robot"), optical_xyz=(0.0, 0.0, 0.0))


def test_base_footprint_for_base_link_drops_the_world_point_by_the_footprint_height() -> None:
    fault = InjectedFault(Fault.WRONG_WORLD_FRAME, "robot", {"used": "base_footprint", "footprint_height_m": 0.07})
    scene, clean = _scene(fault), _scene()
    footprint = _static(scene, "base_link", "base_footprint")
    np.testing.assert_allclose(footprint, pt.transform_from(np.eye(3), [0.0, 0.0, -0.07]), atol=1e-15)
    # base_link's z is vertical (the base drives on the floor), so the whole error is 7 cm straight down.
    down = np.tile([0.0, 0.0, -0.07], (len(clean.robot_world), 1))
    np.testing.assert_allclose(scene.robot_world - clean.robot_world, down, atol=1e-9)
    (expected,) = scene.expected_findings
    assert (expected.fault, expected.hop, expected.estimate) == (
        "wrong_world_frame", "body_to_world", {"used": "base_footprint"})
    assert not expected.names("wrong_world_frame", "body_to_world", {"used": "odom"})


def test_odom_for_map_follows_the_drift() -> None:
    scene = _scene(InjectedFault(Fault.WRONG_WORLD_FRAME, "robot"))
    stamps = scene.timeline.observations.stamp_ns
    expected = _apply(_world_from(scene, "base_link", stamps, world="odom"), _points(scene, PointRole.HOP_BODY))
    np.testing.assert_allclose(scene.robot_world, expected, atol=1e-5)
    assert scene.expected_findings[0].estimate == {"used": "odom"}


def test_stale_pose_held_uses_the_odom_sample_before_tau_minus_hold() -> None:
    hold_s = 0.05
    scene = _scene(InjectedFault(Fault.LATENCY, "robot", {"hold_s": hold_s}))
    tf = scene.timeline.transforms
    odom_stamps = np.sort(tf.stamp_ns[tf.child == "base_link"])
    stamps = scene.timeline.observations.stamp_ns
    held = np.array([odom_stamps[odom_stamps <= s - round(hold_s * 1e9)].max() for s in stamps])
    assert np.all((stamps - held >= 50_000_000) & (stamps - held < 60_000_000))  # 100 Hz odom
    expected = _apply(_world_from(scene, "base_link", held), _points(scene, PointRole.HOP_BODY))
    np.testing.assert_allclose(scene.robot_world, expected, atol=1e-5)
    (finding,) = scene.expected_findings
    assert finding.estimate["offset_s"] == pytest.approx(-0.055)
    assert finding.estimate_within({"offset_s": -0.051})
    assert not finding.estimate_within({"offset_s": -0.045})


def test_mount_published_inverted_in_the_data() -> None:
    scene = _scene(InjectedFault(Fault.INVERTED_TRANSFORM, "data", {"hop": "camera_to_body"}), evidence="reference")
    truth = pt.transform_from(Rotation.from_euler("y", 30.0, degrees=True).as_matrix(), [0.30, 0.0, 1.20])
    np.testing.assert_allclose(_static(scene, "base_link", "camera_link"), pt.invert_transform(truth), atol=1e-12)
    # The robot was right: what it acted on lands on the object.
    assert np.median(np.linalg.norm(scene.robot_world - scene.object_world, axis=1)) < 0.01
    assert scene.expected_findings[0].estimate == {"edge": ["base_link", "camera_link"]}


@pytest.mark.parametrize("where", ["robot", "data"])
def test_camera_info_of_twice_the_resolution(where: str) -> None:
    scene = _scene(InjectedFault(Fault.INTRINSICS, where, {"scale": 2.0}))  # type: ignore[arg-type]
    clean = _scene()
    obs = scene.timeline.observations
    if where == "data":
        # A 1280x960 calibration on 640x480 images: fx, fy, cx, cy all doubled.
        np.testing.assert_allclose(scene.timeline.cameras.K[0], [[1200, 0, 640], [0, 1200, 480], [0, 0, 1]])
        np.testing.assert_allclose(scene.robot_world, clean.robot_world, atol=1e-12)
    else:
        np.testing.assert_allclose(scene.timeline.cameras.K[0], [[600, 0, 320], [0, 600, 240], [0, 0, 1]])
        z = _points(clean, PointRole.HOP_CAMERA)[:, 2]
        expected = np.c_[(obs.u - 640) / 1200 * z, (obs.v - 480) / 1200 * z, z]
        np.testing.assert_allclose(_points(scene, PointRole.HOP_CAMERA), expected, atol=1e-12)
    assert scene.expected_findings[0].estimate == {"scale": 2.0}


@pytest.mark.parametrize("fault", [
    InjectedFault(Fault.AXIS_FLIP, "data", {"used": "base_link"}),
    InjectedFault(Fault.LATENCY, "data", {"hold_s": 0.05}),
    InjectedFault(Fault.WRONG_WORLD_FRAME, "data", {"used": "base_footprint"}),
    InjectedFault(Fault.AXIS_FLIP, "robot", {"used": "base_link"}),
    InjectedFault(Fault.WRONG_WORLD_FRAME, "robot", {"used": "mast"}),
])
def test_faults_that_cannot_live_there_are_refused(fault: InjectedFault) -> None:
    with pytest.raises(SceneError):
        _scene(fault)


def test_the_generator_imports_nothing_of_the_replay_or_the_analysis() -> None:
    code = ("import sys, framechain.sim; "
            "print(sorted(m for m in sys.modules if m.startswith(('framechain.replay', 'framechain.analysis'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
