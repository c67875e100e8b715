"""The camera-motion fit on synthetic rotations: offset sign, hand-eye mount, link, focal, observability.

Link orientations are smooth rotations built with scipy; the "measured" camera rotations are
``X^T R(t0 - d)^T R(t1 - d) X`` for a camera whose frames are late by ``d``, plus noise: the
fit must return ``offset_s = -d``, ``X``, and intervals that hold the truth.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain.analysis.egomotion import (
    EgoMotionFitOptions,
    LinkMotion,
    Measure,
    fit_camera_motion,
    fit_link,
    translation_prior,
)
from framechain.arrays import FloatArray
from framechain.timeline import EgoMotionTable

FPS = 30
DURATION_S = 5.0


def link_motion(name: str, seed: int, *, axes: int = 3) -> LinkMotion:
    """A link turning smoothly (sums of sines per rotation-vector component), sampled at 30 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(DURATION_S * FPS)) / FPS
    rotvec = np.zeros((t.size, 3))
    for axis in range(axes):
        for _ in range(2):
            rotvec[:, axis] += rng.uniform(0.2, 0.4) * np.sin(rng.uniform(0.8, 2.5) * t + rng.uniform(0, 6))
    stamps = np.round(t * 1e9).astype(np.int64)
    xyz = 0.3 * np.column_stack([np.sin(t), np.cos(0.7 * t), 0.2 * t])
    return LinkMotion(name, stamps, Rotation.from_rotvec(rotvec).as_quat(), xyz)


def measured(
    link: LinkMotion, mount: Rotation, late_s: float, *, noise_deg: float = 0.02, seed: int = 0,
    spans: tuple[int, ...] = (1, 3), focal_scale: float = 1.0,
) -> EgoMotionTable:
    """The camera rotations a camera on ``link`` with mount ``mount`` whose frames are ``late_s`` late sees."""
    rng = np.random.default_rng(seed)
    t = (link.stamps_ns - link.stamps_ns[0]) * 1e-9
    truth = Rotation.from_quat(link.quat_xyzw)
    fine = np.arange(0.0, t[-1], 0.001)
    from scipy.spatial.transform import Slerp

    at = Slerp(t, truth)
    first = np.concatenate([np.arange(t.size - s) for s in spans])
    second = np.concatenate([np.arange(t.size - s) + s for s in spans])
    keep = (t[first] - late_s >= 0) & (t[second] - late_s <= fine[-1])
    first, second = first[keep], second[keep]
    cam = mount.inv() * at(t[first] - late_s).inv() * at(t[second] - late_s) * mount
    rotvec = cam.as_rotvec()
    rotvec[:, :2] *= focal_scale
    rotvec += np.deg2rad(noise_deg) * rng.normal(size=rotvec.shape)
    n = first.size
    return EgoMotionTable(
        frame=np.full(n, "cam_optical"), stamp0_ns=link.stamps_ns[first], stamp1_ns=link.stamps_ns[second],
        quat_xyzw=Rotation.from_rotvec(rotvec).as_quat(), direction=np.full((n, 3), np.nan),
        tracks=np.full(n, 100), inliers=np.full(n, 90), residual_px=np.full(n, 0.2), parallax_px=np.zeros(n),
    )


def constant(table: EgoMotionTable) -> Measure:
    return lambda _prior, **_options: table


MOUNT = Rotation.from_euler("xyz", [100.0, -20.0, 35.0], degrees=True)


def angle_deg(a: FloatArray, b: Rotation) -> float:
    return float(np.rad2deg((Rotation.from_quat(a).inv() * b).magnitude()))


@pytest.mark.parametrize("late_s", [0.0, 0.080, -0.045])
def test_late_frames_give_a_negative_offset_and_the_mount(late_s: float) -> None:
    link = link_motion("gripper_link", 1)
    fit = fit_link(measured(link, MOUNT, late_s), link)
    assert fit is not None
    assert fit.offset_s == pytest.approx(-late_s, abs=0.001)
    # 0.02 deg of noise per component and pair leave about 0.05 deg in the mount.
    assert angle_deg(fit.q_link_cam, MOUNT) < 0.15
    assert fit.residual_deg == pytest.approx(np.sqrt(3) * 0.02, rel=0.2)


def test_the_camera_is_named_with_its_link_and_the_declared_mount_error_measured() -> None:
    links = [link_motion("left_gripper_link", 1), link_motion("right_gripper_link", 2), link_motion("base", 3)]
    declared = MOUNT * Rotation.from_rotvec(np.deg2rad(7.0) * np.array([0.0, 0.6, 0.8]))
    table = measured(links[0], MOUNT, 0.05)
    fit = fit_camera_motion(constant(table), [dataclass_without_xyz(link) for link in links], camera="wrist",
                            declared_link="left_gripper_link", declared_q_link_cam=declared.as_quat())
    assert fit.link == "left_gripper_link"
    assert not fit.wrong_link
    assert fit.alternatives == ()
    assert fit.offset_s == pytest.approx(-0.05, abs=0.001)
    assert 0 < fit.offset_interval_s[1] - fit.offset_interval_s[0] < 0.005
    assert fit.mount_error is not None
    assert fit.mount_error.angle_deg == pytest.approx(7.0, abs=0.15)
    assert np.allclose(fit.mount_error.axis, [0.0, 0.6, 0.8], atol=0.01)
    assert fit.focal_scale == pytest.approx(1.0, abs=0.01)
    assert fit.offset_observable
    assert fit.mount_observable
    assert next(f.link for f in fit.links) == "left_gripper_link"
    assert fit.links[1].residual_deg > 10 * fit.links[0].residual_deg


def test_intervals_hold_the_truth_in_most_episodes() -> None:
    # 95% block-bootstrap intervals; on these synthetic episodes they run narrow (about 0.8-0.9
    # coverage, the spread across episodes is 1.2-1.6 times the bootstrap's): at least 8 of 12.
    link = dataclass_without_xyz(link_motion("gripper_link", 1))
    declared = MOUNT * Rotation.from_rotvec(np.deg2rad(7.0) * np.array([0.0, 0.6, 0.8]))
    offsets = angles = 0
    for seed in range(12):
        fit = fit_camera_motion(constant(measured(link, MOUNT, 0.05, seed=seed)), [link], camera="wrist",
                                declared_link="gripper_link", declared_q_link_cam=declared.as_quat())
        assert fit.mount_error is not None
        offsets += fit.offset_interval_s[0] <= -0.05 <= fit.offset_interval_s[1]
        angles += fit.mount_error.interval_deg[0] <= 7.0 <= fit.mount_error.interval_deg[1]
    assert offsets >= 8
    assert angles >= 8


def dataclass_without_xyz(link: LinkMotion) -> LinkMotion:
    """Synthetic rotations ignore the translation prior: no positions, no refinement."""
    return LinkMotion(link.link, link.stamps_ns, link.quat_xyzw)


def test_a_camera_declared_on_the_other_arm_is_found_on_its_own() -> None:
    links = [link_motion("left_gripper_link", 1), link_motion("right_gripper_link", 2)]
    table = measured(links[1], MOUNT, 0.0)
    fit = fit_camera_motion(constant(table), [dataclass_without_xyz(link) for link in links], camera="wrist",
                            declared_link="left_gripper_link", declared_q_link_cam=MOUNT.as_quat())
    assert fit.link == "right_gripper_link"
    assert fit.wrong_link
    assert fit.mount_error is None
    assert any("moves with right_gripper_link, not with the declared left_gripper_link" in n for n in fit.notes)


def test_focal_length_implied_by_the_rotation_scale() -> None:
    # Intrinsics assumed 25% too long: rotations across the optical axis read 0.8 of the truth.
    link = link_motion("gripper_link", 4)
    table = measured(link, MOUNT, 0.0, focal_scale=0.8)
    fit = fit_camera_motion(constant(table), [dataclass_without_xyz(link)], camera="wrist",
                            declared_link="gripper_link", declared_q_link_cam=MOUNT.as_quat())
    assert fit.focal_scale == pytest.approx(0.8, abs=0.02)
    assert fit.focal_scale_interval[0] <= 0.8 + 0.02
    assert fit.focal_scale_interval[1] >= 0.8 - 0.02


def test_a_camera_that_does_not_turn_shows_nothing() -> None:
    link = link_motion("gripper_link", 5)
    still = measured(link, MOUNT, 0.0, noise_deg=0.0)
    still = EgoMotionTable(**{**{k: getattr(still, k) for k in EgoMotionTable.COLUMNS},
                              "quat_xyzw": np.tile([0.0, 0.0, 0.0, 1.0], (len(still), 1))})
    fit = fit_camera_motion(constant(still), [dataclass_without_xyz(link)], camera="front",
                            declared_link="gripper_link", declared_q_link_cam=MOUNT.as_quat())
    assert fit.link == ""
    assert not fit.offset_observable
    assert not fit.mount_observable
    assert np.isnan(fit.offset_s)
    assert "camera front does not turn" in fit.notes[0]
    assert "not observable" in fit.notes[0]


def test_a_link_turning_about_one_axis_leaves_the_mount_unobservable_about_it() -> None:
    link = link_motion("wrist_roll_link", 6, axes=1)
    table = measured(link, MOUNT, 0.03)
    fit = fit_camera_motion(constant(table), [dataclass_without_xyz(link)], camera="wrist",
                            declared_link="wrist_roll_link", declared_q_link_cam=MOUNT.as_quat())
    # The link turns about its x axis alone: the mount about x is not seen (kept as declared), the rest is.
    (axis,) = fit.mount_unobservable_axes
    assert abs(axis[0]) > 0.99
    assert fit.mount_observable
    assert any("turned about one axis only" in n for n in fit.notes)
    assert fit.offset_s == pytest.approx(-0.03, abs=0.002)  # the offset still shows


def test_translation_prior_is_the_camera_centre_motion_in_the_earlier_optical_frame() -> None:
    link = link_motion("gripper_link", 7)
    mount_xyz = np.array([0.05, 0.0, -0.03])
    prior = translation_prior(link, MOUNT.as_quat(), mount_xyz, 0.0)
    i0, i1 = np.array([10, 50, 100]), np.array([11, 53, 101])
    got = prior(link.stamps_ns[i0], link.stamps_ns[i1])
    rot = Rotation.from_quat(link.quat_xyzw)
    centre = link.xyz + rot.apply(mount_xyz)
    expected = (rot[i0] * MOUNT).inv().apply(centre[i1] - centre[i0])
    assert np.allclose(got, expected / np.linalg.norm(expected, axis=1, keepdims=True), atol=1e-9)
    outside = prior(link.stamps_ns[-2:-1], link.stamps_ns[-1:] + 10**9)
    assert np.isnan(outside).all()


def test_too_few_pairs_is_said() -> None:
    link = link_motion("gripper_link", 8)
    table = measured(link, MOUNT, 0.0).take(np.arange(5))
    assert fit_link(table, link, EgoMotionFitOptions(min_pairs=20)) is None
    fit = fit_camera_motion(constant(table), [dataclass_without_xyz(link)], camera="wrist",
                            declared_link="gripper_link", declared_q_link_cam=MOUNT.as_quat())
    assert fit.link == ""
    assert "fewer than 20 measured frame pairs" in fit.notes[0]


def test_the_links_rotation_between_shifted_frame_times_is_scipys_slerp() -> None:
    """Pairs that share frames (consecutive and chained) get the link's rotation between their stamps shifted by each
    offset, as scipy's Slerp interpolates it; times past the link's span take its end."""
    from scipy.spatial.transform import Slerp

    from framechain.analysis.egomotion.solve import Orientations, Pairs, link_rotvecs

    link = link_motion("gripper_link", seed=5)
    t = (link.stamps_ns - link.stamps_ns[0]) * 1e-9
    frames = np.arange(0.013, 4.9, 1 / 18.6)  # a camera's frames between the link's samples
    first = np.concatenate([np.arange(frames.size - s) for s in (1, 3)])
    second = np.concatenate([np.arange(frames.size - s) + s for s in (1, 3)])
    pairs = Pairs(t0=frames[first], t1=frames[second], rotvec=np.zeros((first.size, 3)), weight=np.ones(first.size))
    offsets = np.array([-0.2, -0.0137, 0.0, 0.05])
    got = link_rotvecs(Orientations(link, int(link.stamps_ns[0])), pairs, offsets)
    slerp = Slerp(t, Rotation.from_quat(link.quat_xyzw))
    for k, offset in enumerate(offsets):
        a = slerp(np.clip(pairs.t0 + offset, t[0], t[-1]))
        b = slerp(np.clip(pairs.t1 + offset, t[0], t[-1]))
        np.testing.assert_allclose(got[k], (a.inv() * b).as_rotvec(), atol=1e-9)
