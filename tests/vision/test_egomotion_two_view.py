"""Rotation between two frames from bearing vectors, for many pairs at once, against scipy's rotations.

Scenes are random points; bearings are computed here with plain vector maths (``X0 = R X1 + t``).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from framechain.arrays import FloatArray
from framechain.vision.threads import sharing_threads
from framechain.vision.two_view import (
    SPLIT_PAIRS,
    PairBatch,
    off_flow_residuals,
    rotation_matrices,
    rotations_along_translation,
    rotations_ransac,
    translation_directions,
)

FOCAL = 180.0


def scene_pair(
    rng: np.random.Generator, n: int, *, rotation_deg: float, translation_m: float, depth_m: tuple[float, float],
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Bearings (b0, b1) of n points seen from two cameras with ``X0 = R X1 + t``; returns R and t too."""
    axis = rng.normal(size=3)
    rot = Rotation.from_rotvec(np.deg2rad(rotation_deg) * axis / np.linalg.norm(axis)).as_matrix()
    direction = rng.normal(size=3)
    t = translation_m * direction / np.linalg.norm(direction)
    # Points in camera 0 within a 60-degree cone, at depths drawn in depth_m.
    xy = rng.uniform(-0.55, 0.55, (n, 2))
    rays = np.column_stack([xy, np.ones(n)])
    points0 = rays / np.linalg.norm(rays, axis=1, keepdims=True) * rng.uniform(*depth_m, (n, 1))
    points1 = (points0 - t) @ rot  # X1 = R^T (X0 - t)
    b0 = points0 / np.linalg.norm(points0, axis=1, keepdims=True)
    b1 = points1 / np.linalg.norm(points1, axis=1, keepdims=True)
    return b0, b1, rot, t


def batch_of(pairs: list[tuple[FloatArray, FloatArray]]) -> PairBatch:
    width = max(len(b0) for b0, _b1 in pairs)
    b0 = np.tile([0.0, 0.0, 1.0], (len(pairs), width, 1))
    b1 = b0.copy()
    valid = np.zeros((len(pairs), width), dtype=bool)
    for i, (a, b) in enumerate(pairs):
        b0[i, : len(a)], b1[i, : len(a)], valid[i, : len(a)] = a, b, True
    return PairBatch(b0, b1, valid)


def angle_deg(a: FloatArray, b: FloatArray) -> float:
    return float(np.rad2deg(Rotation.from_matrix(a.T @ b).magnitude()))


def test_rotation_matrices_match_scipy() -> None:
    rotvec = np.random.default_rng(1).normal(size=(50, 3))
    rotvec[0] = 0.0
    assert np.allclose(rotation_matrices(rotvec), Rotation.from_rotvec(rotvec).as_matrix(), atol=1e-12)


def test_ransac_finds_a_pure_rotation_among_outliers() -> None:
    rng = np.random.default_rng(2)
    pairs, truths, outliers = [], [], []
    for n in (40, 120, 80):
        b0, b1, rot, _t = scene_pair(rng, n, rotation_deg=3.0, translation_m=0.0, depth_m=(1.0, 5.0))
        bad = rng.random(n) < 0.3  # 30% of the matches are wrong
        b1[bad] = b1[rng.permutation(n)][bad]
        pairs.append((b0, b1))
        truths.append(rot)
        outliers.append(bad & (np.einsum("ij,mj,mi->m", rot, b1, b0) < np.cos(2.0 / FOCAL)))
    found, inliers = rotations_ransac(batch_of(pairs), 2.0 / FOCAL, hypotheses=64, rng=np.random.default_rng(0))
    for i, rot in enumerate(truths):
        assert angle_deg(found[i], rot) < 1e-9
        n = len(pairs[i][0])
        assert not inliers[i, :n][outliers[i]].any()
        assert inliers[i, :n][~outliers[i]].all()
        assert not inliers[i, n:].any()  # padding is never an inlier


def test_near_points_bias_a_rotation_only_fit_but_not_one_along_the_translation() -> None:
    # A wrist camera: 6 mm of translation over a table 0.25-0.5 m away, 2 degrees of rotation.
    rng = np.random.default_rng(4)
    pairs, rotations, translations = [], [], []
    for _ in range(5):
        b0, b1, rot, t = scene_pair(rng, 150, rotation_deg=2.0, translation_m=0.006, depth_m=(0.25, 0.5))
        pairs.append((b0, b1))
        rotations.append(rot)
        translations.append(t)
    batch = batch_of(pairs)
    rotation_only, inliers = rotations_ransac(batch, 3.0 / FOCAL, hypotheses=64, rng=np.random.default_rng(0))
    biased = [angle_deg(rotation_only[i], r) for i, r in enumerate(rotations)]
    assert np.median(biased) > 0.3  # the translation is read as rotation (unless it is along the optical axis)
    direction = np.array([t / np.linalg.norm(t) for t in translations])
    refined, at_refined = rotations_along_translation(batch, rotation_only, direction, batch.valid.astype(float),
                                                      1.0 / FOCAL, iterations=30)
    for i, rot in enumerate(rotations):
        assert angle_deg(refined[i], rot) < 1e-6
    residual = np.linalg.norm(off_flow_residuals(batch, refined, direction), axis=-1)
    assert residual[batch.valid].max() < 1e-8
    # The residuals the refinement returns are those, at its rotations and at the rotation-only ones alike.
    np.testing.assert_allclose(at_refined[batch.valid], residual[batch.valid], rtol=0, atol=1e-12)
    _same, at_start = rotations_along_translation(batch, rotation_only, direction, batch.valid.astype(float),
                                                  1.0 / FOCAL, iterations=0)
    start = np.linalg.norm(off_flow_residuals(batch, rotation_only, direction), axis=-1)
    assert start[batch.valid].max() > 1e-4  # far from zero: a real comparison, not of two zeros
    np.testing.assert_allclose(at_start[batch.valid], start[batch.valid], rtol=1e-9, atol=1e-15)
    # Given the right rotation, the translation direction is measured back, sign included.
    measured = translation_directions(batch, refined, batch.valid.astype(float))
    assert np.allclose(measured, direction, atol=1e-6)
    assert inliers.sum(axis=1).min() > 0


def test_a_wrong_translation_direction_leaves_points_unexplained() -> None:
    rng = np.random.default_rng(5)
    b0, b1, rot, t = scene_pair(rng, 100, rotation_deg=1.0, translation_m=0.01, depth_m=(0.3, 0.6))
    batch = batch_of([(b0, b1)])
    wrong = np.cross(t, [0.0, 0.0, 1.0])
    residual = off_flow_residuals(batch, rot[None], (wrong / np.linalg.norm(wrong))[None])
    assert np.median(np.linalg.norm(residual[0], axis=1)) * FOCAL > 1.0


def test_a_match_at_the_epipole_keeps_its_whole_residual() -> None:
    """A point straight along the translation shows no flow, so no depth explains any of its residual: the
    refinement's residual there is the whole of ``R b1`` across ``b0``, as :func:`off_flow_residuals` gives it."""
    rng = np.random.default_rng(7)
    b0, b1, rot, t = scene_pair(rng, 30, rotation_deg=3.0, translation_m=0.02, depth_m=(0.3, 1.0))
    direction = t / np.linalg.norm(t)
    b0[0] = direction  # a match at the epipole ...
    tilt = Rotation.from_rotvec([0.002, -0.001, 0.0]).as_matrix()
    b1[0] = tilt @ rot.T @ direction  # ... 2.2 mrad off what the motion predicts
    batch = PairBatch(b0[None], b1[None], np.ones((1, 30), dtype=bool))
    _refined, residual = rotations_along_translation(batch, rot[None], direction[None], batch.valid.astype(float),
                                                     1.0 / FOCAL, iterations=0)
    expected = np.linalg.norm(off_flow_residuals(batch, rot[None], direction[None]), axis=-1)
    assert expected[0, 0] > 2e-3
    np.testing.assert_allclose(residual[0], expected[0], rtol=1e-9, atol=1e-15)


def test_pairs_split_over_threads_measure_the_same_to_the_last_bit() -> None:
    """Each pair's refinement and RANSAC are its own: split into blocks on two threads (as one camera on two cores
    is), the rotations, residuals and inliers are those of one block, bit for bit, and right (scipy's rotations, the
    scene's own)."""
    rng = np.random.default_rng(11)
    pairs, rotations, translations = [], [], []
    for _ in range(2 * SPLIT_PAIRS + 7):
        b0, b1, rot, t = scene_pair(rng, int(rng.integers(20, 60)), rotation_deg=2.0, translation_m=0.006,
                                    depth_m=(0.25, 0.5))
        noisy = b1 + rng.normal(scale=0.3 / FOCAL, size=b1.shape)
        pairs.append((b0, noisy / np.linalg.norm(noisy, axis=1, keepdims=True)))
        rotations.append(rot)
        translations.append(t / np.linalg.norm(t))
    batch = batch_of(pairs)
    start = np.repeat(np.eye(3)[None], len(pairs), axis=0)
    direction = np.array(translations)
    with sharing_threads(1):
        one = rotations_along_translation(batch, start, direction, batch.valid.astype(float), 1.0 / FOCAL, 10)
        ransac_one = rotations_ransac(batch, 3.0 / FOCAL, hypotheses=32, rng=np.random.default_rng(5))
    with sharing_threads(2):
        split = rotations_along_translation(batch, start, direction, batch.valid.astype(float), 1.0 / FOCAL, 10)
        ransac_split = rotations_ransac(batch, 3.0 / FOCAL, hypotheses=32, rng=np.random.default_rng(5))
    assert np.array_equal(one[0], split[0])
    assert np.array_equal(one[1], split[1])
    assert np.array_equal(ransac_one[0], ransac_split[0])
    assert np.array_equal(ransac_one[1], ransac_split[1])
    errors = [angle_deg(split[0][i], rot) for i, rot in enumerate(rotations)]
    assert np.median(errors) < 0.25  # from the identity, 2 deg away; 0.3 px of noise on 20-60 points
