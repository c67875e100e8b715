"""Bounds: what a log's evidence can see of each fault family, and the smallest fault of it framechain would have
found; checked by injecting faults at twice and half the reported bound.

The faults are injected with maths independent of framechain's: generated scenes from
:mod:`framechain.sim` (the generator's own transforms and projection), and a copy of the shared
tagslam_stairs bag with the odometry re-stamped by rosbags' own writer.
"""

from __future__ import annotations

import functools
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.analysis.evidence.replayed import replay_chain
from framechain.analysis.model.chain import ChainInputs, Perturbation, evaluate
from framechain.analysis.verdict.bounds import observations_for
from framechain.catalogue import Fault
from framechain.config.chain import ChainConfig, ChainEvidence
from framechain.geometry.camera import CameraModel
from framechain.sim import InjectedFault, SceneSpec, generate
from tests.helpers.realdata import ARUCO_IMAGES_BAG, aruco_images_chain
from tests.helpers.stairs import recorded_attribution, restamped_bag, stairs_chain


def _bounds(result: Any) -> dict[tuple[str, str], dict[str, Any]]:
    return {(b["fault"], b["hop"]): b for b in result.to_json()["bounds"]}


def _size(bound: dict[str, Any]) -> float:
    (value,) = bound["min_detectable"].values()
    return float(value)


def _finding(result: Any, family: str, hop: str, *, actionable: bool = False) -> dict[str, Any] | None:
    """The finding of the family at the hop (``actionable``: only one worth acting on, not a note)."""
    faults = ("rotation_error", "missing_rotation") if family == "rotation_error" else (family,)
    return next((f for f in result.to_json()["findings"] if f["fault"] in faults and f["hop"] == hop
                 and (f["actionable"] or not actionable)), None)


def _statistical_size(bound: dict[str, Any]) -> float:
    (value,) = bound["statistical_min_detectable"].values()
    return float(value)


# -- a camera that does not move ----------------------------------------------------------------
def test_a_fixed_camera_over_a_static_target_cannot_show_latency_or_its_mount() -> None:
    """A camera fixed over an arena, its mount turned 5 deg: a verdict of "no fault" would be wrong. A fixed
    camera over static targets shows no latency, mount rotation or scale: the verdict says so."""
    turned = InjectedFault(Fault.ROTATION_ERROR, "data", {"angle_deg": 5.0, "axis": [0.0, 1.0, 0.0]})
    scene = generate(SceneSpec(seed=4, duration_s=6.0, evidence="static", fixed_camera=True, faults=(turned,)))
    # Independently: the generator's /tf puts base_link at one place in map at every camera frame.
    tf = scene.timeline.transforms
    stamps = scene.timeline.observations.stamp_ns
    poses = []
    for stamp in (stamps.min(), stamps.max()):
        pose = Rotation.identity(), np.zeros(3)
        for parent, child in (("map", "odom"), ("odom", "base_link")):
            rows = np.flatnonzero((tf.parent == parent) & (tf.child == child))
            k = rows[np.argmin(np.abs(tf.stamp_ns[rows] - stamp))]
            rot = Rotation.from_quat(tf.quat_xyzw[k])
            pose = pose[0] * rot, pose[0].apply(tf.translation[k]) + pose[1]
        poses.append(pose)
    assert np.linalg.norm(poses[0][1] - poses[1][1]) < 1e-3
    assert (poses[0][0].inv() * poses[1][0]).magnitude() < 1e-3

    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    bounds = _bounds(result)
    for key in (("latency", "body_to_world"), ("rotation_error", "camera_to_body"),
                ("translation_error", "camera_to_body"), ("depth_scale", "pixel_to_camera"),
                ("intrinsics", "pixel_to_camera")):
        assert bounds[key]["observable"] is False, bounds[key]
        assert bounds[key]["min_detectable"] is None
        assert "does not move" in bounds[key]["why"]
    assert _finding(result, "rotation_error", "camera_to_body") is None
    assert result.verdict.startswith("Nothing could be checked")
    assert ("not observable here: pose latency (the body does not move while the targets are seen); mount rotation, "
            "mount translation, depth scale and intrinsics scale (the camera does not move relative to the static "
            "targets)") in result.verdict
    # The same turn seen from a moving robot is found, at its size.
    moving = generate(SceneSpec(seed=4, duration_s=6.0, evidence="static", faults=(turned,)))
    found = _finding(pipeline.run(moving.timeline, moving.chain, bootstrap=0).attributed(), "rotation_error",
                     "camera_to_body")
    assert found is not None
    assert found["estimate"]["angle_deg"] == pytest.approx(5.0, abs=0.5)


def test_without_evidence_nothing_could_be_checked() -> None:
    scene = generate(SceneSpec(seed=2, duration_s=4.0, evidence="static"))
    chain = replace(scene.chain, evidence=ChainEvidence())
    doc = pipeline.run(scene.timeline, chain, bootstrap=0).attributed().to_json()
    assert doc["bounds"]
    assert all(b["observable"] is False and b["min_detectable"] is None for b in doc["bounds"])
    assert {b["fault"] for b in doc["bounds"]} == {"latency", "rotation_error", "translation_error", "depth_scale",
                                                   "intrinsics"}
    assert "nothing could be checked" in doc["verdict"]


# -- the bound is honest: 2x found, 0.5x not -----------------------------------------------------
def _scene_fault(family: str, where: str, size: float, sign: float, axis_link: list[float] | None,
                 pitch_deg: float) -> InjectedFault:
    """A fault of the bound's family and ``size`` for the generator (its own maths)."""
    if family == "latency":
        return InjectedFault(Fault.LATENCY, where, {"offset_s": sign * size})  # type: ignore[arg-type]
    if family == "rotation_error":  # the bound's axis is in camera_link; the generator turns in base_link
        axis = Rotation.from_euler("y", pitch_deg, degrees=True).apply(np.asarray(axis_link, dtype=float))
        return InjectedFault(Fault.ROTATION_ERROR, where,  # type: ignore[arg-type]
                             {"angle_deg": sign * size, "axis": axis.tolist()})
    if family == "translation_error":  # the bound's direction is in the mount's parent, base_link, as the generator's
        return InjectedFault(Fault.TRANSLATION_ERROR, where,  # type: ignore[arg-type]
                             {"offset_m": (sign * size * np.asarray(axis_link, dtype=float)).tolist()})
    if family == "depth_scale":
        return InjectedFault(Fault.DEPTH_SCALE, where, {"factor": 1.0 + sign * size})  # type: ignore[arg-type]
    # The bound is that of the harder of K's variants to see: another lens (the focal length alone).
    return InjectedFault(Fault.INTRINSICS, where,  # type: ignore[arg-type]
                         {"scale": 1.0 + sign * size, "variant": "focal"})


@pytest.mark.parametrize(("level", "where", "seed"), [("static", "data", 1), ("hops", "robot", 2)])
def test_generated_faults_at_twice_the_bound_are_found_and_at_half_mostly_not(level: str, where: str,
                                                                              seed: int) -> None:
    """Each family's bound is the larger of what the noise allows and what moves the error by the 1 mm tolerance: a
    fault twice it is a finding to act on, one half of it is not (at most a note); and half the noise's own bound is
    no finding at all."""
    spec = SceneSpec(seed=seed, duration_s=6.0, evidence=level)  # type: ignore[arg-type]
    clean = generate(spec)
    bounds = _bounds(pipeline.run(clean.timeline, clean.chain, bootstrap=0).attributed())
    observable = {k: b for k, b in bounds.items() if b["observable"]}
    assert {k[0] for k in observable} == {"latency", "rotation_error", "translation_error", "depth_scale",
                                          "intrinsics"}
    found_at_half = 0
    for (family, hop), bound in observable.items():
        size, statistical = _size(bound), _statistical_size(bound)
        assert statistical <= size
        assert bound["limited_by"] == ("noise" if statistical == size else "tolerance")
        cases = [(2.0 * size, 1.0, True), (0.5 * size, -1.0, True)]
        if statistical < size:
            cases.append((0.5 * statistical, 1.0, False))
        for injected, sign, actionable in cases:
            fault = _scene_fault(family, where, injected, sign, bound.get("axis"), spec.mount_pitch_deg)
            scene = generate(replace(spec, faults=(fault,)))
            result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
            finding = _finding(result, family, hop, actionable=actionable)
            if injected > size:
                assert finding is not None, (family, injected)
                if family == "latency":  # the estimate within half the bound of the truth
                    assert finding["estimate"]["offset_s"] == pytest.approx(sign * injected, abs=size / 2)
            else:
                found_at_half += finding is not None
    assert found_at_half <= 1


# -- the shared stairs bag with the tutorial's chain: its bound, and a fault twice that size ----------
@functools.cache
def _stairs_bound(realdata: Path) -> float:
    """The pose latency bound of the stairs bag as recorded (seconds), computed once per process."""
    return _size(_bounds(recorded_attribution(realdata))[("latency", "body_to_world")])


@pytest.fixture
def stairs_bound(realdata: Path) -> float:
    return _stairs_bound(realdata)


def test_stairs_latency_bound_is_20_ms_or_better(stairs_bound: float) -> None:
    assert 0.0 < stairs_bound <= 0.020


@pytest.mark.parametrize("factor", [2.0, 0.5])
def test_stairs_odometry_restamped_by_twice_the_bound_is_found_within_half_of_it(
    realdata: Path, tmp_path: Path, stairs_bound: float, factor: float,
) -> None:
    shift_s = factor * stairs_bound
    bag = restamped_bag(realdata, tmp_path / "restamped.bag", round(shift_s * 1e9))
    chain = stairs_chain(realdata)
    finding = _finding(pipeline.run(bag, chain, bootstrap=0).attributed(), "latency", "body_to_world",
                       actionable=True)
    if factor == 2.0:
        # Odometry stamped late by the shift: the pose that fits a detection at tau is the one stamped tau + shift.
        assert finding is not None
        assert finding["estimate"]["offset_s"] == pytest.approx(shift_s, abs=stairs_bound / 2)
    else:
        assert finding is None


# -- the pieces ------------------------------------------------------------------------------
def test_observations_for_turns_world_points_back_into_pixels_and_depths() -> None:
    """The inverse the bounds use to remove noise and to inject faults: the chain under a perturbation
    maps the rewritten observations onto the asked world points."""
    scene = generate(SceneSpec(seed=5, duration_s=3.0, evidence="static", optical_xyz=(0.0, 0.015, 0.0)))
    replayed = replay_chain(scene.timeline, scene.chain)
    result = replayed.replay
    camera = CameraModel.from_table(scene.timeline.cameras, result.main_camera_row())
    inputs = ChainInputs.from_replay(result, replayed.buffer, camera)
    rng = np.random.default_rng(11)
    target = evaluate(inputs, Perturbation())[2] + rng.normal(0.0, 0.02, (len(inputs), 3))
    pert = Perturbation(depth_factor=1.07, focal_scale=0.96, principal_scale=0.96,
                        rotvec_mount=np.array([0.02, -0.01, 0.03]), pose_offset_s=0.012)
    moved = observations_for(inputs, pert, target)
    np.testing.assert_allclose(evaluate(moved, pert)[2], target, atol=1e-9)
    # The scene's world point of the object, seen through the recorded chain: the generator's truth.
    clean = observations_for(inputs, Perturbation(), np.tile(scene.object_world, (len(inputs), 1)))
    np.testing.assert_allclose(evaluate(clean, Perturbation())[2], np.tile(scene.object_world, (len(inputs), 1)),
                               atol=1e-9)


def test_one_image_of_markers_cannot_show_a_latency(realdata: Path) -> None:
    """The fiducials bag holds one JPEG (seven ArUco markers) against a declared reference point: no
    motion, so no latency; the other families only at sizes a single view allows."""
    chain = ChainConfig.from_dict(aruco_images_chain(
        {"markers": {"dictionary": "DICT_5X5_1000", "size_m": 0.14}, "reference_point": [1.0, 0.0, 0.3]}))
    result = pipeline.run(realdata / ARUCO_IMAGES_BAG, chain, bootstrap=0).attributed()
    assert result.counts()["replayed"] == 7
    bounds = _bounds(result)
    assert bounds[("latency", "body_to_world")]["observable"] is False
    assert "does not move" in bounds[("latency", "body_to_world")]["why"]
    rotation = bounds[("rotation_error", "camera_to_body")]
    # One view of markers in front of the camera: a turn about the line of sight (near the optical z
    # axis, the camera's own frame being the mount's link here) moves them by the noise only.
    (blind,) = rotation["unobservable_axes"]
    assert np.linalg.norm(blind) == pytest.approx(1.0, abs=1e-3)
    assert abs(blind[2]) > np.cos(np.deg2rad(30.0))
    assert _size(rotation) > 5.0  # the other axes, from seven points: only a coarse bound
    assert "not observable here: pose latency" in result.verdict


def _held_bag(realdata: Path, out: Path, frames: int) -> Path:
    """The fiducials bag's one real image (and its CameraInfo) as a fixed camera records it: ``frames``
    copies 100 ms apart, header stamps moved with them (rosbags' own writer)."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    with AnyReader([realdata / ARUCO_IMAGES_BAG]) as reader, Writer(out) as writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
                 for c in reader.connections}
        image = next(m for m in reader.messages() if m[0].topic.endswith("image/compressed"))
        info = next(m for m in reader.messages() if m[0].topic.endswith("camera_info"))
        for k in range(frames):
            for conn, t, raw in (info, image):
                msg: Any = reader.deserialize(raw, conn.msgtype)
                stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec + k * 100_000_000
                msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 10**9)
                writer.write(conns[conn.id], t + k * 100_000_000, store.serialize_ros1(msg, conn.msgtype))
    return out


@pytest.mark.parametrize("turned_deg", [0.0, 5.0])
def test_a_real_fixed_camera_over_static_markers_cannot_show_latency_or_its_mount(
    realdata: Path, tmp_path: Path, turned_deg: float,
) -> None:
    """The same on a real image: a fixed camera over static markers (the fiducials bag's JPEG held
    for 12 frames), its mount as declared or turned 5 deg: latency and the mount rotation are not
    observable, and the verdict says nothing could be checked, not "no fault"."""
    mount = Rotation.from_quat([-0.5, 0.5, -0.5, 0.5]) * Rotation.from_rotvec(np.deg2rad(turned_deg) * np.array(
        [0.0, 1.0, 0.0]))
    chain = ChainConfig.from_dict(aruco_images_chain(
        {"markers": {"dictionary": "DICT_5X5_1000", "size_m": 0.14}, "static_target": True},
        tuple(mount.as_quat().tolist())))
    bag = _held_bag(realdata, tmp_path / "held.bag", 12)
    result = pipeline.run(bag, chain, bootstrap=0).attributed()
    assert result.metric == "static_spread"
    assert result.counts()["replayed"] == 7 * 12  # seven markers in every frame
    bounds = _bounds(result)
    latency, rotation = bounds[("latency", "body_to_world")], bounds[("rotation_error", "camera_to_body")]
    assert latency["observable"] is False
    assert latency["min_detectable"] is None
    assert "the body does not move" in latency["why"]
    assert rotation["observable"] is False
    assert rotation["min_detectable"] is None
    assert "the camera does not move relative to the static targets" in rotation["why"]
    assert result.findings == ()
    assert result.verdict.startswith("Nothing could be checked")
    assert "not observable here: pose latency" in result.verdict
    assert "mount rotation, mount translation, depth scale and intrinsics scale (the camera does not move" in \
        result.verdict
