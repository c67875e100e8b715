"""timeline/quaternion.py (the one quaternion module; replay and adapters use it) against scipy's
Rotation on random inputs (components first, x y z w)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain.geometry.rotations import (
    IDENTITY,
    compose,
    homogeneous,
    invert,
    kabsch,
    quat_angle,
    quat_angle_between,
    quat_conjugate,
    quat_from_matrix,
    quat_from_rotvec,
    quat_from_rpy,
    quat_multiply,
    quat_rotate,
    quat_to_matrix,
    quat_to_rotvec,
    quat_to_rpy,
)
from framechain.geometry.transforms import invert_rows, transform_points
from tests.helpers.reference_maths import assert_same_rotation, random_quats

N = 2000


def test_multiply_is_scipy_composition(rng: np.random.Generator) -> None:
    a, b = random_quats(rng, N), random_quats(rng, N)
    ours = quat_multiply(a.T, b.T).T
    theirs = (Rotation.from_quat(a) * Rotation.from_quat(b)).as_quat()
    assert_same_rotation(ours, theirs, atol=1e-15)
    # The Hamilton product itself, not only the rotation: no sign flips.
    np.testing.assert_allclose(np.linalg.norm(ours, axis=1), 1.0, atol=1e-15)


def test_multiply_broadcasts_one_against_many(rng: np.random.Generator) -> None:
    a, b = random_quats(rng, 1), random_quats(rng, N)
    ours = quat_multiply(a.T, b.T).T
    assert ours.shape == (N, 4)
    assert_same_rotation(ours, (Rotation.from_quat(a[0]) * Rotation.from_quat(b)).as_quat(), atol=1e-15)
    np.testing.assert_array_equal(quat_multiply(IDENTITY[:, None], b.T).T, b)


def test_conjugate_is_scipy_inverse(rng: np.random.Generator) -> None:
    q = random_quats(rng, N)
    qt = q.T.copy()
    ours = quat_conjugate(qt).T
    assert_same_rotation(ours, Rotation.from_quat(q).inv().as_quat(), atol=1e-15)
    np.testing.assert_array_equal(qt, q.T)  # input untouched
    np.testing.assert_allclose(quat_multiply(qt, ours.T).T, np.tile(IDENTITY, (N, 1)), atol=1e-15)


def test_rotate_is_scipy_apply(rng: np.random.Generator) -> None:
    q, v = random_quats(rng, N), rng.normal(size=(N, 3)) * 10
    np.testing.assert_allclose(quat_rotate(q.T, v.T).T, Rotation.from_quat(q).apply(v), atol=1e-13)
    # One rotation, many vectors.
    np.testing.assert_allclose(quat_rotate(q[0][:, None], v.T).T, Rotation.from_quat(q[0]).apply(v), atol=1e-13)


ANGLES = [0.0, 1e-300, 1e-12, 1e-8, 1e-6, 9.9e-7, 1.01e-6, 1e-4, 0.3, 1.0, 3.0, np.pi - 1e-6, np.pi - 1e-9,
          np.pi]


@pytest.mark.parametrize("angle", ANGLES)
def test_from_rotvec_matches_scipy_at_every_angle(rng: np.random.Generator, angle: float) -> None:
    axes = rng.normal(size=(200, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    rotvec = axes * angle
    ours = quat_from_rotvec(rotvec.T).T
    theirs = Rotation.from_rotvec(rotvec).as_quat()
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-15)  # same sign: w = cos(angle/2) >= 0


def test_from_rotvec_random(rng: np.random.Generator) -> None:
    rotvec = rng.normal(size=(N, 3)) * 2
    np.testing.assert_allclose(
        quat_from_rotvec(rotvec.T).T, Rotation.from_rotvec(rotvec).as_quat(), rtol=0, atol=1e-15
    )


def test_from_rpy_is_scipy_fixed_axis_euler(rng: np.random.Generator) -> None:
    rpy = rng.uniform(-np.pi, np.pi, (200, 3))
    assert_same_rotation(quat_from_rpy(rpy.T).T, Rotation.from_euler("xyz", rpy).as_quat())
    # URDF rpy (fixed axes x then y then z) of a quarter turn about each axis, by hand.
    h = np.sqrt(0.5)
    np.testing.assert_allclose(quat_from_rpy(np.array([np.pi / 2, 0.0, 0.0])), [h, 0, 0, h], atol=1e-15)
    np.testing.assert_allclose(quat_from_rpy(np.array([0.0, 0.0, np.pi / 2])), [0, 0, h, h], atol=1e-15)


def test_chain_mount_rotations_use_the_shared_maths(rng: np.random.Generator) -> None:
    from framechain.config.chain import ChainConfig

    for rpy, rotvec in zip(rng.uniform(-3, 3, (20, 3)), rng.uniform(-2, 2, (20, 3)), strict=True):
        mounts = ChainConfig.from_dict({"mounts": [{"parent": "a", "child": "b", "rpy": rpy.tolist()},
                                                   {"parent": "b", "child": "c", "rotvec": rotvec.tolist()}]}).mounts
        assert_same_rotation(np.array([mounts[0].quat_xyzw]), Rotation.from_euler("xyz", rpy).as_quat()[None])
        assert_same_rotation(np.array([mounts[1].quat_xyzw]), Rotation.from_rotvec(rotvec).as_quat()[None])


@pytest.mark.parametrize("angle", [a for a in ANGLES if a < np.pi - 1e-7])
def test_to_rotvec_matches_scipy_away_from_pi(rng: np.random.Generator, angle: float) -> None:
    axes = rng.normal(size=(200, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    q = Rotation.from_rotvec(axes * angle).as_quat()
    q[::2] *= -1  # both signs of the same rotation give the same rotation vector
    ours = quat_to_rotvec(q.T).T
    np.testing.assert_allclose(ours, Rotation.from_quat(q).as_rotvec(), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(quat_angle(q.T), np.abs(angle), rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("angle", [np.pi - 1e-6, np.pi - 1e-9, np.pi])
def test_to_rotvec_near_pi_is_the_same_rotation(rng: np.random.Generator, angle: float) -> None:
    # Near pi, v and -v are (almost) the same rotation: compare rotations and angles, not vectors.
    axes = rng.normal(size=(200, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    q = Rotation.from_rotvec(axes * angle).as_quat()
    q[::2] *= -1
    ours = quat_to_rotvec(q.T).T
    np.testing.assert_allclose(np.linalg.norm(ours, axis=1), angle, rtol=1e-12)
    assert_same_rotation(Rotation.from_rotvec(ours).as_quat(), q, atol=1e-12)
    np.testing.assert_allclose(quat_angle(q.T), angle, rtol=1e-12)


def test_rotvec_round_trip_random(rng: np.random.Generator) -> None:
    q = random_quats(rng, N)
    back = quat_from_rotvec(quat_to_rotvec(q.T)).T
    assert_same_rotation(back, q, atol=1e-14)
    np.testing.assert_allclose(quat_to_rotvec(q.T).T, Rotation.from_quat(q).as_rotvec(), atol=1e-13)
    np.testing.assert_allclose(quat_angle(q.T), Rotation.from_quat(q).magnitude(), atol=1e-13)


def test_compose_and_invert_are_scipy_products(rng: np.random.Generator) -> None:
    q_ab, q_bc = random_quats(rng, N), random_quats(rng, N)
    t_ab, t_bc = rng.normal(size=(N, 3)), rng.normal(size=(N, 3))
    t_ac, q_ac = compose(t_ab.T, q_ab.T, t_bc.T, q_bc.T)
    r_ab = Rotation.from_quat(q_ab)
    np.testing.assert_allclose(t_ac.T, r_ab.apply(t_bc) + t_ab, atol=1e-13)
    assert_same_rotation(q_ac.T, (r_ab * Rotation.from_quat(q_bc)).as_quat(), atol=1e-15)
    t_ba, q_ba = invert(t_ab.T, q_ab.T)
    np.testing.assert_allclose(t_ba.T, -r_ab.inv().apply(t_ab), atol=1e-13)
    assert_same_rotation(q_ba.T, r_ab.inv().as_quat(), atol=1e-15)


def test_compose_takes_components_with_float_constants(rng: np.random.Generator) -> None:
    """A kinematic chain's fixed joint: Python floats beside per-frame arrays, broadcast."""
    q_ab = random_quats(rng, 1)[0]
    t_ab = rng.normal(size=3)
    q_bc, t_bc = random_quats(rng, N), rng.normal(size=(N, 3))
    t_ac, q_ac = compose(tuple(float(c) for c in t_ab), tuple(float(c) for c in q_ab),  # type: ignore[arg-type]
                         tuple(t_bc.T), tuple(q_bc.T))  # type: ignore[arg-type]
    r_ab = Rotation.from_quat(q_ab)
    np.testing.assert_allclose(t_ac.T, r_ab.apply(t_bc) + t_ab, atol=1e-13)
    assert_same_rotation(q_ac.T, (r_ab * Rotation.from_quat(q_bc)).as_quat(), atol=1e-15)


def test_homogeneous_and_from_matrix_match_scipy(rng: np.random.Generator) -> None:
    q, t = random_quats(rng, N), rng.normal(size=(N, 3))
    m = homogeneous(q.T, t.T)
    np.testing.assert_allclose(m[:, :3, :3], Rotation.from_quat(q).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(m[:, :3, 3], t)
    np.testing.assert_array_equal(m[:, 3], np.tile([0.0, 0.0, 0.0, 1.0], (N, 1)))
    assert_same_rotation(quat_from_matrix(m[:, :3, :3]).T, q, atol=1e-14)
    assert quat_from_matrix(np.eye(3)).shape == (4,)


def test_to_rpy_is_tf2_get_rpy_and_inverts_from_rpy(rng: np.random.Generator) -> None:
    q = random_quats(rng, N)
    rpy = quat_to_rpy(q.T).T
    np.testing.assert_allclose(rpy, Rotation.from_quat(q).as_euler("xyz"), atol=1e-12)
    assert_same_rotation(quat_from_rpy(rpy.T).T, q, atol=1e-14)
    assert quat_to_rpy(q[0]).shape == (3,)
    # Looking straight down (pitch pi/2): any split of roll and yaw is right, and no warning is raised.
    down = quat_from_rpy(np.array([0.3, np.pi / 2, -0.2]))
    assert_same_rotation(quat_from_rpy(quat_to_rpy(down))[None], down[None], atol=1e-12)
    # By hand: a quarter turn about z is yaw pi/2.
    h = np.sqrt(0.5)
    np.testing.assert_allclose(quat_to_rpy(np.array([0.0, 0.0, h, h])), [0.0, 0.0, np.pi / 2], atol=1e-15)


def test_to_matrix_and_angle_between_match_scipy(rng: np.random.Generator) -> None:
    a, b = random_quats(rng, N), random_quats(rng, N)
    np.testing.assert_allclose(quat_to_matrix(a.T), Rotation.from_quat(a).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(quat_to_matrix(a[0]), Rotation.from_quat(a[0]).as_matrix(), atol=1e-14)
    theirs = (Rotation.from_quat(a).inv() * Rotation.from_quat(b)).magnitude()
    np.testing.assert_allclose(quat_angle_between(a.T, b.T), theirs, atol=1e-12)
    np.testing.assert_allclose(quat_angle_between(a.T, -a.T), 0.0, atol=1e-7)  # q and -q: the same rotation


def test_row_transforms_match_scipy(rng: np.random.Generator) -> None:
    q, t, p = random_quats(rng, N), rng.normal(size=(N, 3)), rng.normal(size=(N, 3))
    r = Rotation.from_quat(q)
    np.testing.assert_allclose(transform_points(t, q, p), r.apply(p) + t, atol=1e-13)
    t_inv, q_inv = invert_rows(t, q)
    np.testing.assert_allclose(t_inv, -r.inv().apply(t), atol=1e-13)
    assert_same_rotation(q_inv, r.inv().as_quat(), atol=1e-15)
    np.testing.assert_allclose(transform_points(t_inv, q_inv, transform_points(t, q, p)), p, atol=1e-12)
    # One transform for every point broadcasts.
    np.testing.assert_allclose(transform_points(t[0], q[0], p), Rotation.from_quat(q[0]).apply(p) + t[0], atol=1e-13)


def test_kabsch_matches_scipy_align_vectors() -> None:
    rng = np.random.default_rng(7)
    for _ in range(5):
        b = rng.normal(size=(30, 3))
        truth = Rotation.random(random_state=rng)
        a = truth.apply(b) + 0.01 * rng.normal(size=b.shape)
        w = rng.uniform(0.5, 2.0, 30)
        expected, _rssd = Rotation.align_vectors(a, b, weights=w)
        got = kabsch(np.einsum("n,ni,nj->ij", w, a, b)[None])[0]
        assert np.allclose(got, expected.as_matrix(), atol=1e-10)
        assert np.linalg.det(got) == pytest.approx(1.0)


def test_rotations_as_rows_read_products_inverses_and_rotation_vectors_as_written() -> None:
    from framechain.geometry.rotations import (
        Inverse,
        RotationVector,
        angle_of,
        matrix_of,
        quat_of,
        rotate_by,
        rotvec_of,
    )

    rng = np.random.default_rng(3)
    a, b = Rotation.random(5, random_state=1), Rotation.random(5, random_state=2)
    turn = rng.normal(size=3) * 0.3
    # (a, b) is a b; Inverse inverts; a matrix reads as the same rotation; nested tuples group.
    assert_same_rotation(quat_of((a.as_quat(), b.as_matrix())), (a * b).as_quat())
    assert_same_rotation(quat_of((Inverse(a.as_quat()), b.as_quat())), (a.inv() * b).as_quat())
    assert_same_rotation(quat_of((a.as_quat(), RotationVector(turn))), (a * Rotation.from_rotvec(turn)).as_quat())
    np.testing.assert_allclose(matrix_of(a.as_quat()), a.as_matrix(), atol=1e-15)
    np.testing.assert_allclose(rotvec_of((Inverse(a.as_matrix()), a.as_quat())), np.zeros((5, 3)), atol=1e-7)
    np.testing.assert_allclose(angle_of((Inverse(a.as_quat()), b.as_quat())), (a.inv() * b).magnitude(), atol=1e-12)
    vectors = rng.normal(size=(5, 3))
    np.testing.assert_allclose(rotate_by(Inverse((a.as_quat(), b.as_quat())), vectors), (a * b).inv().apply(vectors),
                               atol=1e-12)
    with pytest.raises(TypeError, match="an array of quaternions or matrices"):
        quat_of((0.0, 0.0, 0.0, 1.0))  # type: ignore[arg-type]
