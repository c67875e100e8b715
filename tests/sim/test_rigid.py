"""The scene generator's own maths against DESIGN.md's worked numbers and pytransform3d."""

from __future__ import annotations

import numpy as np
import pytest
import pytransform3d.rotations as pr
import pytransform3d.transformations as pt
from scipy.spatial.transform import Rotation

from framechain.sim import rigid

IDENTITY_XYZW = [0.0, 0.0, 0.0, 1.0]


def _random_pose(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A random translation and a random unit xyzw quaternion (drawn by numpy, not scipy)."""
    q = rng.normal(size=4)
    return rng.uniform(-3.0, 3.0, 3), q / np.linalg.norm(q)


def _pt_matrix(translation: np.ndarray, quat_xyzw: np.ndarray) -> np.ndarray:
    pq = np.r_[translation, pr.quaternion_wxyz_from_xyzw(quat_xyzw)]
    return np.asarray(pt.transform_from_pq(pq))


def test_worked_numbers_of_the_design() -> None:
    K = rigid.intrinsic_matrix(600.0, 600.0, 320.0, 240.0)
    p_cam = rigid.back_project(K, np.array([380.0]), np.array([210.0]), np.array([2.0]))
    np.testing.assert_allclose(p_cam, [[0.2, -0.1, 2.0]], atol=1e-12)
    p_body = rigid.apply(rigid.matrix([0.30, 0.0, 0.80], IDENTITY_XYZW), p_cam)
    np.testing.assert_allclose(p_body, [[0.5, -0.1, 2.8]], atol=1e-12)
    p_world = rigid.apply(rigid.matrix([1.0, 0.5, 0.0], IDENTITY_XYZW), p_body)
    np.testing.assert_allclose(p_world, [[1.5, 0.4, 2.8]], atol=1e-12)
    u, v = rigid.project(K, p_cam)
    np.testing.assert_allclose([u[0], v[0]], [380.0, 210.0], atol=1e-9)


def test_matrices_inverse_apply_and_rows_match_pytransform3d() -> None:
    rng = np.random.default_rng(7)
    poses = [_random_pose(rng) for _ in range(50)]
    translations = np.array([t for t, _ in poses])
    quats = np.array([q for _, q in poses])
    ours = rigid.matrices(translations, quats)
    theirs = np.array([_pt_matrix(t, q) for t, q in poses])
    np.testing.assert_allclose(ours, theirs, atol=1e-12)
    np.testing.assert_allclose(rigid.inverse(ours), [pt.invert_transform(m) for m in theirs], atol=1e-12)
    points = rng.uniform(-5.0, 5.0, (50, 3))
    expected = np.array([pt.transform(m, np.r_[p, 1.0])[:3] for m, p in zip(theirs, points, strict=True)])
    np.testing.assert_allclose(rigid.apply(ours, points), expected, atol=1e-12)
    # Composition is left to right: T_a_c = T_a_b @ T_b_c applies T_b_c first.
    composed = ours[:-1] @ ours[1:]
    chained = np.array([pt.transform(theirs[i], pt.transform(theirs[i + 1], np.r_[points[i], 1.0]))[:3]
                        for i in range(49)])
    np.testing.assert_allclose(rigid.apply(composed, points[:-1]), chained, atol=1e-11)
    back_t, back_q = rigid.to_rows(ours)
    np.testing.assert_allclose(back_t, translations, atol=1e-12)
    same_sign = np.sign(np.sum(back_q * quats, axis=1))[:, None]  # q and -q are one rotation
    np.testing.assert_allclose(back_q * same_sign, quats, atol=1e-12)


def test_interpolation_is_tf2s_lerp_and_slerp() -> None:
    rng = np.random.default_rng(11)
    stamps = np.sort(rng.choice(np.arange(0, 2_000_000_000, 1_000), 8, replace=False)).astype(np.int64)
    # Neighbouring samples less than 90 deg apart, so the short way round is unambiguous.
    rotvecs = np.cumsum(rng.normal(0.0, 0.5, (8, 3)), axis=0)
    quats = Rotation.from_rotvec(rotvecs).as_quat()
    translations = rng.uniform(-1.0, 1.0, (8, 3))
    queries = rng.integers(stamps[0], stamps[-1], 40)
    ours = rigid.interpolate(stamps, translations, quats, queries)
    for query, got in zip(queries, ours, strict=True):
        i = int(np.searchsorted(stamps, query, side="right") - 1)
        j = min(i + 1, stamps.size - 1)
        ratio = 0.0 if j == i else (query - stamps[i]) / (stamps[j] - stamps[i])
        translation = (1 - ratio) * translations[i] + ratio * translations[j]
        q0, q1 = (pr.quaternion_wxyz_from_xyzw(q) for q in (quats[i], quats[j]))
        if np.dot(q0, q1) < 0:  # pytransform3d's slerp does not take the short way by itself
            q1 = -q1
        rotation = pr.matrix_from_quaternion(pr.quaternion_slerp(q0, q1, ratio))
        np.testing.assert_allclose(got[:3, :3], rotation, atol=1e-9)
        np.testing.assert_allclose(got[:3, 3], translation, atol=1e-12)
    exact = rigid.interpolate(stamps, translations, quats, stamps)  # at a sample: the sample itself
    np.testing.assert_allclose(exact, [_pt_matrix(t, q) for t, q in zip(translations, quats, strict=True)],
                               atol=1e-12)
    with pytest.raises(ValueError, match="extrapolation"):
        rigid.interpolate(stamps, translations, quats, np.array([stamps[-1] + 1]))


def test_zero_order_hold_takes_the_latest_sample_at_or_before() -> None:
    stamps = np.array([10, 20, 30, 40], dtype=np.int64)
    np.testing.assert_array_equal(rigid.held(stamps, np.array([10, 19, 20, 39, 45])), [10, 10, 20, 30, 40])
    with pytest.raises(ValueError, match="before the first sample"):
        rigid.held(stamps, np.array([9]))


def test_projection_round_trip_with_an_anisotropic_camera() -> None:
    rng = np.random.default_rng(3)
    K = rigid.intrinsic_matrix(910.0, 905.0, 641.5, 362.25)
    points = np.c_[rng.uniform(-1, 1, (30, 2)), rng.uniform(0.3, 6.0, 30)]
    u, v = rigid.project(K, points)
    # Independent: K @ p / z.
    homogeneous = points @ K.T
    np.testing.assert_allclose(np.c_[u, v], homogeneous[:, :2] / homogeneous[:, 2:], atol=1e-9)
    np.testing.assert_allclose(rigid.back_project(K, u, v, points[:, 2]), points, atol=1e-12)
