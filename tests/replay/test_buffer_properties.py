"""Property tests: vectorised lookups on random frame trees against one-at-a-time references.

References: :func:`tests.helpers.reference_maths.reference_lookup` (bracketing samples found by hand, lerp, scipy
Slerp, 4x4 matrices composed along the path) and pytransform3d's TemporalTransformManager.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from framechain.replay import LookupStatus, TransformBuffer
from framechain.timeline import TransformTable
from tests.helpers.reference_maths import OK, RefEdge, assert_same_rotation, random_quats, reference_lookup

MS = 1_000_000
PROFILE = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def positive_chain(q: np.ndarray) -> np.ndarray:
    """The same rotations with signs chosen so that consecutive quaternions have a positive dot."""
    out = q.copy()
    for i in range(1, len(out)):
        if np.dot(out[i - 1], out[i]) < 0:
            out[i] = -out[i]
    return out


@st.composite
def forests(draw: st.DrawFn, *, connected: bool = False, shared_stamps: bool = False) -> list[RefEdge]:
    """Random frame trees (a forest unless ``connected``): f1..fn each with a parent among earlier frames."""
    n_frames = draw(st.integers(2, 7))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    grid = np.sort(rng.choice(np.arange(0, 1000), size=draw(st.integers(2, 6)), replace=False)) * MS
    edges = []
    for i in range(1, n_frames):
        if not connected and draw(st.integers(0, 5)) == 0:
            continue  # f{i} starts a new tree
        parent = f"f{draw(st.integers(0, i - 1))}"
        static = draw(st.booleans())
        if static:
            k = 1
            stamps = np.array([draw(st.integers(-10**12, 10**12))])
        elif shared_stamps:
            stamps, k = grid, grid.size
        else:
            k = draw(st.integers(1, 6))
            stamps = np.sort(rng.choice(np.arange(0, 1000), size=k, replace=False)) * MS
        scale = draw(st.sampled_from([0.05, 1.0, 4.0]))  # rotation change between samples
        base = Rotation.from_quat(random_quats(rng, 1))
        steps = Rotation.from_rotvec(rng.normal(size=(k, 3)) * scale)
        quats = positive_chain((base * steps).as_quat())
        edges.append(RefEdge(parent, f"f{i}", stamps, rng.normal(size=(k, 3)) * 3, quats, static))
    return edges


def all_frames(edges: list[RefEdge]) -> list[str]:
    return sorted({e.child for e in edges} | {e.parent for e in edges})


def query_times(edges: list[RefEdge], rng: np.random.Generator) -> np.ndarray:
    stamps = np.concatenate([e.stamps for e in edges if not e.is_static] + [np.array([0, 999 * MS])])
    return np.concatenate([stamps, rng.integers(-100 * MS, 1100 * MS, size=40)])


def build(edges: list[RefEdge]) -> TransformBuffer:
    return TransformBuffer(TransformTable.concat([e.table() for e in edges]))


@PROFILE
@given(edges=forests(), data=st.data())
def test_vectorised_lookup_equals_one_at_a_time_reference(edges: list[RefEdge], data: st.DataObject) -> None:
    if not edges:
        return
    frames = all_frames(edges)
    target = data.draw(st.sampled_from(frames))
    source = data.draw(st.sampled_from(frames))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    times = query_times(edges, rng)
    result = build(edges).lookup(target, source, times)
    mats = result.matrix()
    for i, t in enumerate(times.tolist()):
        status, expected = reference_lookup(edges, target, source, t)
        assert result.status[i] == status, (target, source, t)
        if status == OK:
            np.testing.assert_allclose(mats[i], expected, atol=1e-9)
        else:
            assert np.isnan(result.translation[i]).all()
    # Per-hop samples: every hop's own transform is its edge at that time.
    by_child = {e.child: e for e in edges}
    for hop in result.hops:
        edge = by_child[hop.hop.child]
        for i in np.flatnonzero(hop.status == LookupStatus.OK)[:5].tolist():
            t = int(times[i])
            _, expected = reference_lookup([edge], edge.parent, edge.child, t)
            np.testing.assert_allclose(expected[:3, 3], hop.translation[i], atol=1e-9)
            if not edge.is_static:
                assert hop.stamp_before_ns[i] <= t <= hop.stamp_after_ns[i]
                assert 0.0 <= hop.weight[i] <= 1.0


@PROFILE
@given(edges=forests(), data=st.data())
def test_lookup_composed_with_its_inverse_is_identity(edges: list[RefEdge], data: st.DataObject) -> None:
    if not edges:
        return
    frames = all_frames(edges)
    a, b = data.draw(st.sampled_from(frames)), data.draw(st.sampled_from(frames))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    times = query_times(edges, rng)
    buf = build(edges)
    ab, ba = buf.lookup(a, b, times), buf.lookup(b, a, times)
    np.testing.assert_array_equal(ab.status, ba.status)
    ok = ab.ok
    product = ab.matrix()[ok] @ ba.matrix()[ok]
    np.testing.assert_allclose(product, np.tile(np.eye(4), (int(ok.sum()), 1, 1)), atol=1e-9)


@PROFILE
@given(edges=forests(connected=True, shared_stamps=True), data=st.data())
def test_agrees_with_pytransform3d_temporal_transform_manager(edges: list[RefEdge], data: st.DataObject) -> None:
    from pytransform3d.transform_manager import NumpyTimeseriesTransform, StaticTransform, TemporalTransformManager

    tm = TemporalTransformManager()
    grid = None
    for e in edges:
        if e.is_static:
            tm.add_transform(e.child, e.parent, StaticTransform(
                np.block([[Rotation.from_quat(e.quat_xyzw[0]).as_matrix(), e.translation[0][:, None]],
                          [np.zeros((1, 3)), np.ones((1, 1))]])))
        else:
            grid = e.stamps
            pqs = np.concatenate([e.translation, e.quat_xyzw[:, [3, 0, 1, 2]]], axis=1)
            tm.add_transform(e.child, e.parent, NumpyTimeseriesTransform(e.stamps, pqs))
    if grid is None:
        grid = np.array([0, 999 * MS])
    frames = all_frames(edges)
    target = data.draw(st.sampled_from(frames))
    source = data.draw(st.sampled_from(frames))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    buf = build(edges)

    # At sample stamps every edge is exact: the two libraries agree on the whole transform.
    ours = buf.lookup(target, source, grid)
    assert (ours.status == LookupStatus.OK).all()
    theirs = np.broadcast_to(tm.get_transform_at_time(source, target, grid), (grid.size, 4, 4))  # (4, 4) if same
    np.testing.assert_allclose(ours.matrix(), theirs, atol=1e-9)

    # Between samples pytransform3d interpolates by screw motion (ScLERP): the rotations still agree
    # (ScLERP's rotation is slerp), the translations follow tf2's lerp instead.
    between = np.sort(rng.integers(int(grid[0]), int(grid[-1]), size=30, endpoint=True))
    ours = buf.lookup(target, source, between)
    assert (ours.status == LookupStatus.OK).all()
    theirs = np.broadcast_to(tm.get_transform_at_time(source, target, between), (between.size, 4, 4))
    assert_same_rotation(ours.quat_xyzw, Rotation.from_matrix(theirs[:, :3, :3]).as_quat(), atol=1e-9)
    for i, t in enumerate(between.tolist()):
        _, expected = reference_lookup(edges, target, source, t)
        np.testing.assert_allclose(ours.translation[i], expected[:3, 3], atol=1e-9)


def test_sclerp_and_lerp_really_differ_between_samples() -> None:
    # Guard for the test above: with rotation between samples, ScLERP's translation is not lerp,
    # so comparing pytransform3d translations to ours between samples would be wrong.
    from pytransform3d.transform_manager import NumpyTimeseriesTransform, TemporalTransformManager

    quats = np.array([[0, 0, 0, 1.0], Rotation.from_euler("z", 90, degrees=True).as_quat()])
    trans = np.array([[0.0, 0, 0], [1.0, 1.0, 0]])
    tm = TemporalTransformManager()
    pqs = np.concatenate([trans, quats[:, [3, 0, 1, 2]]], axis=1)
    tm.add_transform("b", "a", NumpyTimeseriesTransform(np.array([0, 10]), pqs))
    buf = build([RefEdge("a", "b", np.array([0, 10]), trans, quats)])
    ours = buf.lookup("a", "b", [5])
    theirs = tm.get_transform_at_time("b", "a", np.array([5]))[0]
    np.testing.assert_allclose(ours.translation[0], [0.5, 0.5, 0.0], atol=1e-15)
    assert np.linalg.norm(theirs[:3, 3] - ours.translation[0]) > 1e-3
    assert_same_rotation(ours.quat_xyzw, [Rotation.from_matrix(theirs[:3, :3]).as_quat()], atol=1e-12)


@pytest.mark.parametrize("n_times", [0, 1, 7])
def test_small_and_empty_time_arrays(n_times: int) -> None:
    edges = [RefEdge("a", "b", np.array([0, 10]), np.zeros((2, 3)), np.tile([0, 0, 0, 1.0], (2, 1)))]
    result = build(edges).lookup("a", "b", np.arange(n_times, dtype=np.int64))
    assert len(result) == n_times
    assert result.translation.shape == (n_times, 3)
    assert result.quat_xyzw.shape == (n_times, 4)
    assert all(len(h.times_ns) == n_times for h in result.hops)
