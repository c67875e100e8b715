"""The shared tagslam_quad_rig: four fisheye cameras in two synced pairs, no pose. framechain's rig chain is
checked against an independent computation: the bag read with rosbags, each tag's centre by OpenCV's
fisheye undistortion and square-marker PnP, put in the rig frame with camera_poses.yaml (T_rig_cam, a position
and a rotation vector) by scipy, and pairs of one tag at one stamp compared (docs/rigs.md: 28 and 39 mm)."""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.analysis.verdict.checks import Bound
from framechain.analysis.verdict.findings import Attribution
from framechain.catalogue import Fault
from framechain.config.chain import ChainConfig
from tests.helpers.realdata import QUAD_RIG

cv2 = pytest.importorskip("cv2")

CAMERAS = {"cam0": "quadruple/bottom_left", "cam1": "quadruple/bottom_right", "cam2": "quadruple/top_left",
           "cam3": "quadruple/top_right"}
FRAME_S = 0.03334  # the cameras' frame period (median step of their stamps)
TURNED = "cam1"


@dataclass(frozen=True)
class Sightings:
    """The independent computation: one row per tag detection."""

    camera: np.ndarray  # camN
    stamp_ns: np.ndarray
    label: np.ndarray
    p_cam: np.ndarray  # (N, 3) tag centre in the camera frame


def _poses(folder: Path) -> dict[str, np.ndarray]:
    raw = yaml.safe_load((folder / "camera_poses.yaml").read_text())
    out = {}
    for name, entry in raw.items():
        pose = entry["pose"]
        matrix = np.eye(4)
        matrix[:3, :3] = Rotation.from_rotvec([pose["rotation"][a] for a in "xyz"]).as_matrix()
        matrix[:3, 3] = [pose["position"][a] for a in "xyz"]
        out[name] = matrix
    return out


@cache
def _sightings(folder: Path) -> Sightings:
    from rosbags.highlevel import AnyReader

    cams = yaml.safe_load((folder / "cameras.yaml").read_text())
    by_topic = {v["tagtopic"]: k for k, v in cams.items()}
    rows: list[tuple[str, int, str, np.ndarray]] = []
    with AnyReader([folder / "tag_detections.bag"]) as reader:
        for connection, _t, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            name = by_topic[connection.topic]
            fx, fy, cx, cy = cams[name]["intrinsics"]
            k = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
            d = np.array(cams[name]["distortion_coeffs"])
            stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
            for tag in msg.apriltags:
                s = 0.15 if tag.id == 44 else 0.125
                px = np.array([[c.x, c.y] for c in tag.corners], float).reshape(-1, 1, 2)
                norm = cv2.fisheye.undistortPoints(px, k, d).reshape(-1, 2)
                obj = np.array([[-s / 2, s / 2, 0], [s / 2, s / 2, 0], [s / 2, -s / 2, 0], [-s / 2, -s / 2, 0]])
                ok, _rvec, tvec = cv2.solvePnP(obj, norm, np.eye(3), None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
                assert ok
                rows.append((name, stamp, str(tag.id), tvec.reshape(3)))
    return Sightings(np.array([r[0] for r in rows]), np.array([r[1] for r in rows], dtype=np.int64),
                     np.array([r[2] for r in rows]), np.stack([r[3] for r in rows]))


def _in_rig(s: Sightings, poses: dict[str, np.ndarray]) -> np.ndarray:
    out = np.empty_like(s.p_cam)
    for name, matrix in poses.items():
        mine = s.camera == name
        out[mine] = s.p_cam[mine] @ matrix[:3, :3].T + matrix[:3, 3]
    return out


def _pair_distances(s: Sightings, p: np.ndarray, a: str, b: str, shift_b_ns: float = 0.0) -> np.ndarray:
    """For each sighting of camera ``a``, the distance to camera ``b``'s track of the same tag at that instant,
    ``b``'s stamps shifted by ``shift_b_ns``: b's two sightings around it interpolated linearly (at most 1.5
    frames apart), or one at the same stamp. Plain loops: the independent computation."""
    out = []
    track: dict[str, list[tuple[float, np.ndarray]]] = {}
    for i in np.flatnonzero(s.camera == b):
        track.setdefault(str(s.label[i]), []).append((float(s.stamp_ns[i]) + shift_b_ns, p[i]))
    for seq in track.values():
        seq.sort(key=lambda x: x[0])
    for i in np.flatnonzero(s.camera == a):
        seq = track.get(str(s.label[i]), [])
        t = float(s.stamp_ns[i])
        times = [x[0] for x in seq]
        j = int(np.searchsorted(times, t))
        if j < len(seq) and abs(times[j] - t) < 1e5:
            out.append(np.linalg.norm(p[i] - seq[j][1]))
        elif 0 < j < len(seq) and times[j] - times[j - 1] <= 1.5 * FRAME_S * 1e9:
            w = (t - times[j - 1]) / (times[j] - times[j - 1])
            out.append(np.linalg.norm(p[i] - ((1 - w) * seq[j - 1][1] + w * seq[j][1])))
    return np.asarray(out)


def _chain_text(folder: Path, poses: dict[str, np.ndarray], turned_deg: float = 0.0,
                axis: tuple[float, float, float] = (1.0, 0.0, 0.0)) -> str:
    lines = ["frames: {body: rig}", "cameras:"]
    for name, frame in CAMERAS.items():
        lines.append(f"  - {{frame: {frame}, detections: /{frame}/tags, calibration: "
                     f"{{file: {folder / 'cameras.yaml'}, camera: {name}}}}}")
    lines.append("mounts:")
    for name, frame in CAMERAS.items():
        rotation = Rotation.from_matrix(poses[name][:3, :3])
        if name == TURNED and turned_deg:
            rotation = rotation * Rotation.from_rotvec(np.deg2rad(turned_deg) * np.array(axis) / np.linalg.norm(axis))
        xyz, rotvec = poses[name][:3, 3].tolist(), rotation.as_rotvec().tolist()
        lines.append(f"  - {{parent: rig, child: {frame}, xyz: {xyz}, rotvec: {rotvec}}}")
    lines += ["evidence:", "  static_target: true", "  tag_size_m: {default: 0.125, 44: 0.15}"]
    return "\n".join(lines) + "\n"


@cache
def _loaded(folder: Path, turned_deg: float, axis: tuple[float, float, float] = (1.0, 0.0, 0.0)) -> pipeline.LoadedRun:
    text = _chain_text(folder, _poses(folder), turned_deg, axis)
    chain = ChainConfig.from_dict(yaml.safe_load(text), where="rig.yaml")
    return pipeline.load_log(folder / "tag_detections.bag", chain)


@cache
def _attributed(folder: Path, case: str) -> Attribution:
    if case == "late":  # bottom_right's detections stamped one frame late
        return _faulty(folder, late_ns=round(FRAME_S * 1e9))
    return _faulty(folder, turned_deg=5.0 if case == "turned" else 0.0)


@cache
def _faulty(folder: Path, turned_deg: float = 0.0, axis: tuple[float, float, float] = (1.0, 0.0, 0.0),
            late_ns: int = 0) -> Attribution:
    """The rig with bottom_right's mount turned ``turned_deg`` about ``axis`` of its own frame in the chain, and its
    detections stamped ``late_ns`` late."""
    loaded = _loaded(folder, turned_deg, axis)
    timeline = loaded.timeline
    if late_ns:
        obs = timeline.observations
        shifted = np.where(obs.camera_frame == CAMERAS[TURNED], obs.stamp_ns + late_ns, obs.stamp_ns)
        timeline = timeline.replace(observations=replace(obs, stamp_ns=shifted))
    return pipeline.run(timeline, loaded.chain, bootstrap=0).attributed()


@pytest.fixture(scope="module")
def rig(realdata: Path) -> Path:
    folder = realdata / QUAD_RIG
    if not (folder / "tag_detections.bag").is_file():
        pytest.skip("tagslam_quad_rig not found")
    return folder


def test_independent_pairs_agree_as_the_readme_says(rig: Path) -> None:
    s = _sightings(rig)
    p = _in_rig(s, _poses(rig))
    bottom = _pair_distances(s, p, "cam0", "cam1")
    top = _pair_distances(s, p, "cam2", "cam3")
    assert np.median(bottom) == pytest.approx(0.028, abs=0.0015)
    assert np.median(top) == pytest.approx(0.039, abs=0.0015)
    assert _pair_distances(s, p, "cam0", "cam2").size == 0  # the pairs never see one tag at once
    inverted = {k: (np.linalg.inv(m) if k in ("cam2", "cam3") else m) for k, m in _poses(rig).items()}
    assert np.median(_pair_distances(s, _in_rig(s, inverted), "cam2", "cam3")) > 0.3  # inverted: ~0.48 m apart


def test_each_camera_is_its_topics_and_replays_as_the_independent_points(rig: Path) -> None:
    loaded = _loaded(rig, 0.0, (1.0, 0.0, 0.0))
    run = pipeline.run(loaded.timeline, loaded.chain, attribute=False)
    result = run.replay
    assert result.counts()["replayed"] == len(result) == 14655
    s = _sightings(rig)
    p = _in_rig(s, _poses(rig))
    obs = result.observations
    mine = {(CAMERAS[c], int(t), str(lab)): q for c, t, lab, q in zip(s.camera, s.stamp_ns, s.label, p, strict=True)}
    theirs = np.array([mine[(str(f), int(t), str(lab))] for f, t, lab in
                       zip(obs.camera_frame, obs.stamp_ns, obs.label, strict=True)])
    assert np.abs(theirs - result.p_world).max() < 1e-6
    assert any("header.frame_id '/quadruple/bottom_left'" in n and "top_right/tags" in n for n in loaded.notes)


@pytest.mark.slow
def test_as_recorded_no_finding_and_the_groups_are_said(rig: Path) -> None:
    result = _attributed(rig, "recorded")
    assert all(f.share <= 0.10 for f in result.findings), [f.to_json() for f in result.findings]
    assert result.rig is not None
    groups = result.to_json()["rig"]["groups"]
    assert groups == [[CAMERAS["cam0"], CAMERAS["cam1"]], [CAMERAS["cam2"], CAMERAS["cam3"]]]
    assert "not observable here: the pose and clock of" in result.verdict
    assert result.error_summary()["median"] == pytest.approx(0.031, abs=0.003)


@pytest.mark.slow
def test_a_mount_turned_5_degrees_is_found_on_that_camera(rig: Path) -> None:
    result = _attributed(rig, "turned")
    top = result.findings[0]
    assert top.fault == Fault.ROTATION_ERROR
    assert top.camera == CAMERAS[TURNED]
    assert abs(top.estimate.angle_deg - 5.0) < 1.0  # type: ignore[union-attr]
    # The fix gives the mount in the chain's form (rotvec); put in the independent computation, the bottom pair
    # agrees again, at least as well as recorded.
    found = re.search(rf"child: {CAMERAS[TURNED]}, xyz: \[([^\]]+)\], rotvec: \[([^\]]+)\]", top.fix)
    assert found is not None, top.fix
    poses = _poses(rig)
    fixed = np.eye(4)
    fixed[:3, :3] = Rotation.from_rotvec([float(v) for v in found.group(2).split(",")]).as_matrix()
    fixed[:3, 3] = [float(v) for v in found.group(1).split(",")]
    s = _sightings(rig)
    turned = dict(poses)
    turned[TURNED] = poses[TURNED] @ _rotation_x(5.0)
    before = np.median(_pair_distances(s, _in_rig(s, turned), "cam0", "cam1"))
    after = np.median(_pair_distances(s, _in_rig(s, {**poses, TURNED: fixed}), "cam0", "cam1"))
    recorded = np.median(_pair_distances(s, _in_rig(s, poses), "cam0", "cam1"))
    assert before > 3 * recorded
    assert after <= recorded + 0.001


@pytest.mark.slow
def test_one_frame_late_is_a_latency_on_that_camera(rig: Path) -> None:
    result = _attributed(rig, "late")
    late = [f for f in result.findings if f.fault == Fault.LATENCY]
    assert late, result.verdict
    assert late[0] is result.findings[0]
    assert late[0].camera == CAMERAS[TURNED]
    estimate = late[0].estimate.offset_s  # type: ignore[union-attr]
    assert abs(estimate + FRAME_S) < 0.15
    # The independent curve: cam1's sightings (stamped a frame late) against cam0's track, cam1 taken as seen at
    # its stamp + offset; its best offset and framechain's agree to within a quarter frame.
    s = _sightings(rig)
    late_s = replace(s, stamp_ns=np.where(s.camera == "cam1", s.stamp_ns + round(FRAME_S * 1e9), s.stamp_ns))
    p = _in_rig(late_s, _poses(rig))
    offsets = np.arange(-0.08, 0.0401, 0.004)
    cost = [np.median(_pair_distances(late_s, p, "cam0", "cam1", shift_b_ns=o * 1e9)) for o in offsets]
    best = float(offsets[int(np.argmin(cost))])
    assert abs(best + FRAME_S) <= 0.01
    assert abs(estimate - best) < FRAME_S / 4


def _rotation_x(degrees: float) -> Any:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(np.deg2rad(degrees) * np.array([1.0, 0.0, 0.0])).as_matrix()
    return out


def _bound(result: Attribution, camera: str, fault: Fault) -> Bound:
    return next(b for b in result.bounds if b.camera == camera and b.fault == fault)


@pytest.mark.slow
def test_bounds_per_camera_say_what_each_camera_can_show(rig: Path) -> None:
    """Every camera has a bound for each sized family: the second camera of each pair measured against the first,
    the first (the gauge) not observable, with why; the verdict names them per camera."""
    result = _attributed(rig, "recorded")
    families = {Fault.LATENCY, Fault.ROTATION_ERROR, Fault.TRANSLATION_ERROR, Fault.DEPTH_SCALE, Fault.INTRINSICS}
    for name, frame in CAMERAS.items():
        mine = {b.fault: b for b in result.bounds if b.camera == frame}
        assert set(mine) == families, (frame, [b.to_json() for b in result.bounds])
        gauge = name in ("cam0", "cam2")
        assert all(b.observable is not gauge for b in mine.values())
        if gauge:
            assert all("sets the gauge of its pair" in b.why for b in mine.values())
    turned = _bound(result, CAMERAS[TURNED], Fault.ROTATION_ERROR)
    assert turned.to_json()["camera"] == CAMERAS[TURNED]
    # A fault within a rig camera's tolerance is no finding: no bound is under it.
    assert turned.size is not None
    assert turned.size >= 2.0
    # Each size says what sets it: the noise, the 1 mm tolerance, or what a cross-check of the cameras can pin on one.
    said = r"No fault above [^;]* latency[^;]*, [^;]* mount rotation[^;]*, [^;]* mount translation[^;]*, [^;]* " \
        r"depth scale[^;]* and [^;]* intrinsics scale \(set by [^;]*\) on camera "
    assert re.search(said + re.escape(CAMERAS[TURNED]), result.verdict), result.verdict
    assert "(set by the rig's cross-check)" in result.verdict
    assert ("not observable here: latency, mount rotation, mount translation, depth scale and intrinsics scale on "
            f"camera {CAMERAS['cam0']}") in result.verdict
    assert all("camera" in b for b in result.to_json()["bounds"])


@pytest.mark.slow
def test_a_mount_turned_twice_its_bound_is_found_on_that_camera(rig: Path) -> None:
    """bottom_right's mount turned by twice its bound about the weakest axis the bound names (in its own frame, the
    mount's link): the top finding, on that camera, the size within half the bound."""
    bound = _bound(_attributed(rig, "recorded"), CAMERAS[TURNED], Fault.ROTATION_ERROR)
    assert bound.size is not None
    assert bound.axis is not None
    result = _faulty(rig, turned_deg=round(2 * bound.size, 3), axis=bound.axis)
    top = result.findings[0]
    assert top.fault == Fault.ROTATION_ERROR, result.verdict
    assert top.camera == CAMERAS[TURNED], result.verdict
    assert abs(top.estimate.angle_deg - 2 * bound.size) < bound.size / 2  # type: ignore[union-attr]


@pytest.mark.slow
def test_stamps_late_by_twice_the_bound_are_found_on_that_camera(rig: Path) -> None:
    """bottom_right's detections stamped late by twice its latency bound: a latency on that camera of minus that
    shift, within half the bound."""
    bound = _bound(_attributed(rig, "recorded"), CAMERAS[TURNED], Fault.LATENCY)
    assert bound.size is not None
    late_s = 2 * bound.size
    result = _faulty(rig, late_ns=round(late_s * 1e9))
    top = result.findings[0]
    assert top.fault == Fault.LATENCY, result.verdict
    assert top.camera == CAMERAS[TURNED], result.verdict
    assert abs(top.estimate.offset_s + late_s) < bound.size / 2  # type: ignore[union-attr]
