"""Static targets (several tags, each static), windows against odometry drift, bearing-only rays,
a latency search over +-1 s, and labels declared moving.

Scenes are built here with independent maths (scipy rotations, a hand-written pinhole): a rig
moves on a known trajectory and watches tags at known world positions; the Timeline tables are
written directly. Assertions compare with the injected truth (stamp offsets, tag positions).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.analysis.evidence.static import fit_static_points, intersect_rays, static_groups
from framechain.analysis.verdict.attribute import AnalysisError, Unattributed
from framechain.catalogue import Fault
from framechain.config.chain import ChainConfig
from framechain.config.errors import ChainConfigError
from framechain.timeline import CameraTable, ObservationTable, Timeline, TransformTable

FX, FY, CX, CY, WIDTH, HEIGHT = 500.0, 500.0, 320.0, 240.0, 640, 480
#: Camera on the rig: 10 cm forward, 20 cm up, looking along the rig's +x (REP-103 optical rotation).
MOUNT_XYZ = np.array([0.10, 0.0, 0.20])
MOUNT = Rotation.from_quat([-0.5, 0.5, -0.5, 0.5])
TAGS = {
    "1": np.array([4.0, 0.5, 1.0]),
    "2": np.array([4.5, -0.6, 0.6]),
    "3": np.array([3.8, 0.0, 1.4]),
    "4": np.array([5.0, 0.8, 0.3]),
}
MOVING_TAG = "9"
RATE_HZ = 5.0


@dataclass(frozen=True)
class Scene:
    timeline: Timeline
    chain: ChainConfig
    truth: dict[str, np.ndarray]


def rig_pose(t: np.ndarray) -> tuple[np.ndarray, Rotation]:
    """True T_map_rig: a hand-held sway (velocity and heading change every second or so)."""
    xyz = np.stack([
        0.6 * np.sin(0.31 * t) + 0.25 * np.sin(1.3 * t),
        0.5 * np.sin(0.23 * t + 1.0) + 0.2 * np.sin(1.7 * t),
        0.1 * np.sin(0.9 * t),
    ], axis=1)
    ypr = np.stack([0.2 * np.sin(0.7 * t) + 0.08 * np.sin(2.1 * t), 0.05 * np.sin(1.1 * t), 0.03 * np.sin(0.5 * t)],
                   axis=1)
    return xyz, Rotation.from_euler("ZYX", ypr)


def tag_position(label: str, t: np.ndarray) -> np.ndarray:
    if label == MOVING_TAG:  # slides sideways, 0.3 m/s at its fastest
        return np.array([4.2, 0.0, 0.8]) + np.stack([np.zeros_like(t), 0.6 * np.sin(0.5 * t), np.zeros_like(t)], 1)
    return np.tile(TAGS[label], (t.size, 1))


def drift(t: np.ndarray, speed_m_per_s: float) -> np.ndarray:
    """Odometry drift: ``speed_m_per_s`` along a heading that turns by 0.05 rad/s (a curve, not a line,
    so that neither a global centre nor one linear creep per log absorbs it)."""
    heading = 0.6 + 0.05 * t
    return speed_m_per_s / 0.05 * np.stack([np.sin(heading) - np.sin(0.6), np.cos(0.6) - np.cos(heading),
                                            0.02 * t], axis=1)


def make_scene(
    *,
    duration_s: float = 30.0,
    offset_s: float = 0.0,
    drift_m_per_s: float = 0.0,
    depth: bool = True,
    moving_tag: bool = False,
    odom_margin_s: float = 2.0,
    seed: int = 7,
    evidence: dict[str, object] | None = None,
) -> Scene:
    """Observations of every tag in view at RATE_HZ; stamps ``offset_s`` early (the pose that explains
    a detection is at stamp + offset_s); the recorded odometry drifts by ``drift_m_per_s``."""
    rng = np.random.default_rng(seed)
    t_capture = np.arange(0.0, duration_s, 1.0 / RATE_HZ)
    xyz, rot = rig_pose(t_capture)
    labels = [*TAGS, *([MOVING_TAG] if moving_tag else [])]
    rows: dict[str, list[np.ndarray]] = {k: [] for k in ("t", "u", "v", "z", "label")}
    for label in labels:
        p_world = tag_position(label, t_capture)
        p_rig = rot.inv().apply(p_world - xyz)
        p_cam = MOUNT.inv().apply(p_rig - MOUNT_XYZ)
        z = p_cam[:, 2]
        u = FX * p_cam[:, 0] / z + CX + rng.normal(0, 0.3, z.size)
        v = FY * p_cam[:, 1] / z + CY + rng.normal(0, 0.3, z.size)
        seen = (z > 0.3) & (u > 0) & (u < WIDTH - 1) & (v > 0) & (v < HEIGHT - 1)
        rows["t"].append(t_capture[seen])
        rows["u"].append(u[seen])
        rows["v"].append(v[seen])
        rows["z"].append(z[seen] + rng.normal(0, 0.003, int(seen.sum())))
        rows["label"].append(np.full(int(seen.sum()), label))
    t = np.concatenate(rows["t"])
    n = t.size
    stamp_ns = np.round((t - offset_s) * 1e9).astype(np.int64) + 10**18
    observations = ObservationTable(
        obs_id=np.arange(n, dtype=np.int64), stamp_ns=stamp_ns, log_time_ns=stamp_ns,
        camera_frame=np.full(n, "cam_optical"), u=np.concatenate(rows["u"]), v=np.concatenate(rows["v"]),
        depth_m=np.concatenate(rows["z"]) if depth else np.full(n, np.nan), label=np.concatenate(rows["label"]),
        score=np.ones(n), source=np.full(n, "/tags"),
    )
    # Odometry at 100 Hz, ``odom_margin_s`` beyond the observations' stamps and capture times.
    t_odom = np.arange(min(0.0, -offset_s) - odom_margin_s, duration_s + max(0.0, -offset_s) + odom_margin_s, 0.01)
    odom_xyz, odom_rot = rig_pose(t_odom)
    odom_xyz = odom_xyz + drift(t_odom, drift_m_per_s)
    transforms = TransformTable.concat([
        TransformTable.from_rows("map", "rig", np.round(t_odom * 1e9).astype(np.int64) + 10**18, odom_xyz,
                                 odom_rot.as_quat(), source="/odom"),
        TransformTable.from_rows("rig", "cam_optical", [0], MOUNT_XYZ, MOUNT.as_quat(), is_static=True,
                                 source="/tf_static"),
    ])
    cameras = CameraTable.from_intrinsics("cam_optical", fx=FX, fy=FY, cx=CX, cy=CY, width=WIDTH, height=HEIGHT)
    chain = ChainConfig.from_dict({
        "frames": {"camera": "cam_optical", "body": "rig", "world": "map"},
        "evidence": {"static_target": True, **(evidence or {})},
    })
    timeline = Timeline(transforms=transforms, cameras=cameras, observations=observations)
    return Scene(timeline, chain, {label: tag_position(label, np.zeros(1))[0] for label in labels})


def _labels_of_replayed(result: object) -> np.ndarray:
    replay = result.replay  # type: ignore[attr-defined]
    out: np.ndarray = replay.observations.label[replay.replayed]
    return out


# -- the maths on its own -----------------------------------------------------------------------
def test_rays_through_a_point_meet_there(rng: np.random.Generator) -> None:
    """Rays from random origins through known points (one per object) intersect at those points."""
    points = rng.uniform(-3, 3, (3, 3))
    group = np.repeat(np.arange(3), 20)
    origin = rng.uniform(-10, 10, (group.size, 3))
    direction = points[group] - origin
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    groups = static_groups(np.array(["a", "b", "c"])[group], np.zeros(group.size, dtype=np.int64))
    for detrend in (False, True):
        got = intersect_rays(origin, direction, groups, detrend=detrend)
        np.testing.assert_allclose(got, points[group], atol=1e-6)


def test_ray_intersection_matches_a_generic_least_squares(rng: np.random.Generator) -> None:
    """Noisy rays: the closed form equals scipy's minimiser of the squared perpendicular distances."""
    from scipy.optimize import least_squares

    point = np.array([1.0, 2.0, 5.0])
    origin = rng.uniform(-2, 2, (15, 3))
    direction = point + rng.normal(0, 0.05, (15, 3)) - origin
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)

    def perpendicular(p: np.ndarray) -> np.ndarray:
        v = p - origin
        return (v - np.sum(v * direction, axis=1, keepdims=True) * direction).ravel()

    expected = least_squares(perpendicular, np.zeros(3), xtol=1e-14, ftol=1e-14).x
    groups = static_groups(np.full(15, "tag"), np.zeros(15, dtype=np.int64))
    got = intersect_rays(origin, direction, groups, detrend=False)
    np.testing.assert_allclose(got[0], expected, atol=1e-7)


def test_windows_split_labels_and_drop_sparse_objects() -> None:
    stamps = np.array([0, 1, 2, 3, 11, 12, 13, 0, 1], dtype=np.int64) * 10**9
    labels = np.array(["a"] * 7 + ["b"] * 2)
    groups = static_groups(labels, stamps, window_s=10.0, min_points=3)
    assert groups.labels == ("a", "a")  # "a" in two windows; "b" seen twice only: not used
    np.testing.assert_array_equal(groups.group, [0, 0, 0, 0, 1, 1, 1, -1, -1])
    np.testing.assert_allclose(groups.tau_s[:4], [-1.5, -0.5, 0.5, 1.5])


# -- attribution ----------------------------------------------------------------------------------
def test_each_label_is_its_own_static_object() -> None:
    scene = make_scene()
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    world = result.replay.p_world[result.replay.replayed]
    global_spread = np.median(np.linalg.norm(world - world.mean(axis=0), axis=1))
    assert global_spread > 0.5  # all tags as one object: metres apart
    assert result.error_summary()["median"] < 0.01  # each against its own: noise
    assert result.findings == ()
    labels = _labels_of_replayed(result)
    for label, truth in scene.truth.items():  # the fitted objects sit on the tags
        fitted = result.evidence_points[labels == label]
        fitted = fitted[np.isfinite(fitted).all(axis=1)]
        assert np.linalg.norm(np.median(fitted, axis=0) - truth) < 0.01, label


@pytest.mark.parametrize("depth", [True, False], ids=["depth", "bearing_only"])
@pytest.mark.parametrize("offset_s", [0.5, -0.35])
def test_stamp_offset_found_over_the_whole_range(offset_s: float, depth: bool) -> None:
    scene = make_scene(offset_s=offset_s, depth=depth, duration_s=30.0 if depth else 20.0)
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    assert result.findings, result.notes
    top = result.findings[0]
    assert (top.fault, top.hop.value) == (Fault.LATENCY, "body_to_world"), [f.model for f in result.findings]
    assert abs(top.estimate.offset_s - offset_s) < 0.01  # type: ignore[union-attr]
    if not depth:
        assert result.counts()["rejected"] == {}  # no depth is not a rejection when rays are the evidence
        assert any(note.startswith("bearing only") for note in result.notes)
        assert all(f.fault != Fault.DEPTH_SCALE for f in result.findings)
        labels = _labels_of_replayed(result)
        for label, truth in scene.truth.items():  # the corrected rays meet on the tags
            fitted = result.evidence_points[labels == label]
            assert np.linalg.norm(np.nanmedian(fitted, axis=0) - truth) < 0.02, label


def test_mount_rotation_seen_from_rays_alone() -> None:
    """The recorded mount rolled by 3 deg about the optical axis: rays alone show it."""
    scene = make_scene(depth=False, duration_s=20.0)
    transforms = scene.timeline.transforms
    recorded = MOUNT * Rotation.from_rotvec(np.deg2rad(3.0) * np.array([0.0, 0.0, 1.0]))
    wrong_mount = TransformTable.concat([
        transforms.take(np.flatnonzero(~transforms.is_static)),
        TransformTable.from_rows("rig", "cam_optical", [0], MOUNT_XYZ, recorded.as_quat(), is_static=True),
    ])
    result = pipeline.run(scene.timeline.replace(transforms=wrong_mount), scene.chain, bootstrap=0).attributed()
    assert [f.fault for f in result.findings] == [Fault.ROTATION_ERROR]
    estimate = result.findings[0].estimate
    assert abs(estimate.angle_deg - 3.0) < 0.2  # type: ignore[union-attr]
    assert abs(abs(estimate.axis[2]) - 1.0) < 0.01  # type: ignore[union-attr]


def test_offset_near_the_ends_of_the_odometry() -> None:
    """Odometry that stops 50 ms past the detections: the offsets searched would push the first and
    last detections out of it, so those are left out of the evidence (said in a note) instead of
    counting against the true offset."""
    scene = make_scene(offset_s=0.5, odom_margin_s=0.05)
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    assert [f.fault for f in result.findings] == [Fault.LATENCY]
    assert abs(result.findings[0].estimate.offset_s - 0.5) < 0.01  # type: ignore[union-attr]
    stamps = scene.timeline.observations.stamp_ns
    odom = scene.timeline.transforms.stamp_ns[~scene.timeline.transforms.is_static]
    near_ends = int(((stamps - 10**9 < odom.min()) | (stamps + 10**9 > odom.max())).sum())  # the +-1 s searched
    assert near_ends > 0
    note = next(n for n in result.notes if "of the ends of the poses not used" in n)
    assert int(note.split(": ")[1].split(" ")[0]) == near_ends


@pytest.mark.parametrize("depth", [True, False], ids=["depth", "bearing_only"])
def test_slow_odometry_drift_is_no_fault(depth: bool) -> None:
    scene = make_scene(drift_m_per_s=0.02, duration_s=40.0 if depth else 25.0, depth=depth)
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    world = result.replay.p_world[result.replay.replayed]
    labels = _labels_of_replayed(result)
    assert [f.model for f in result.findings] == []
    if depth:  # the drift is real: one tag's recorded points wander by most of a metre, and one
        # window over the whole log (a single centre and creep per tag) leaves centimetres of it
        tag = world[labels == "1"]
        assert np.linalg.norm(np.ptp(tag, axis=0)) > 0.4
        whole = make_scene(drift_m_per_s=0.02, duration_s=40.0, evidence={"static_window_s": 1000})
        assert pipeline.run(whole.timeline, whole.chain, bootstrap=0).attributed().error_summary()["median"] > 0.02


def test_ignored_label_drops_a_moving_tag() -> None:
    def per_label_error(result: object) -> dict[str, float]:
        labels = _labels_of_replayed(result)
        errors = result.error_before  # type: ignore[attr-defined]
        return {str(k): float(np.nanmedian(errors[labels == k])) for k in np.unique(labels)}

    moving = make_scene(moving_tag=True, duration_s=20.0)
    spread = pipeline.run(moving.timeline, moving.chain, bootstrap=0).attributed()
    assert per_label_error(spread)[MOVING_TAG] > 0.02  # it moves: its points spread
    ignored = make_scene(moving_tag=True, duration_s=20.0, evidence={"ignore_labels": [int(MOVING_TAG)]})
    result = pipeline.run(ignored.timeline, ignored.chain, bootstrap=0).attributed()
    n_moving = int((ignored.timeline.observations.label == MOVING_TAG).sum())
    counts = result.counts()
    assert counts["rejected"] == {"ignored_label": n_moving}
    assert counts["replayed"] + n_moving == counts["total"] == len(ignored.timeline.observations)
    errors = per_label_error(result)
    assert MOVING_TAG not in errors
    assert max(errors.values()) < 0.01
    assert result.findings == ()
    assert any(f"{n_moving} observations" in note and "ignored_label" in note for note in result.notes)


def test_chain_ignore_labels_and_window() -> None:
    chain = ChainConfig.from_dict({"evidence": {"static_target": True, "ignore_labels": [7, "cup"],
                                                "static_window_s": 4}})
    assert chain.evidence.ignore_labels == ("7", "cup")
    assert chain.evidence.static_window_s == 4.0
    assert ChainConfig.from_dict(chain.to_dict()) == chain
    with pytest.raises(ChainConfigError, match=r"evidence\.ignore_labels"):
        ChainConfig.from_dict({"evidence": {"ignore_labels": [{"id": 3}]}})
    with pytest.raises(ChainConfigError, match=r"evidence\.static_window_s"):
        ChainConfig.from_dict({"evidence": {"static_window_s": -1}})


def test_no_object_seen_often_enough_says_so() -> None:
    """Four labels, at most two sightings of one in a window: no object, one line, no traceback."""
    labels = np.array(["1", "1", "2", "3", "4"])
    stamps = np.array([0, 10**8, 2 * 10**8, 3 * 10**8, 4 * 10**8], dtype=np.int64)
    groups = static_groups(labels, stamps, window_s=5.0)
    assert groups.n_groups == 0
    assert np.isnan(fit_static_points(np.ones((5, 3)), groups)).all()
    assert intersect_rays(np.zeros((0, 3)), np.zeros((0, 3)), groups.take(np.zeros(0, dtype=np.int64))).shape == (0, 3)
    scene = make_scene(duration_s=20.0)
    chain = replace(scene.chain, evidence=replace(scene.chain.evidence, static_window_s=1e-6))
    made = pipeline.run(scene.timeline, chain, bootstrap=0)
    assert made.not_attributed is not None
    assert made.not_attributed.reason is Unattributed.STATIC_TARGET  # the static objective's error, said as it is
    with pytest.raises(AnalysisError, match=r"no object seen at least 3 times in one 1e-06 s window") as err:
        made.attributed()
    assert "at most 1 sighting" in str(err.value)
