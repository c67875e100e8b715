"""TransformBuffer against tf2's lookup semantics, checked with independent maths."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from framechain.replay import (
    LATEST,
    ConnectivityError,
    ExtrapolationError,
    FrameGraphError,
    LookupStatus,
    TransformBuffer,
)
from framechain.timeline import InvalidTransformError, TransformTable
from tests.helpers.reference_maths import (
    FUTURE,
    PAST,
    RefEdge,
    assert_same_rotation,
    matrix,
    random_quats,
    reference_lookup,
)

S = 1_000_000_000  # one second in ns
IDENT = [0.0, 0.0, 0.0, 1.0]


def yaw(deg: float) -> list[float]:
    out: list[float] = Rotation.from_euler("z", deg, degrees=True).as_quat().tolist()
    return out


def buffer_of(*edges: RefEdge) -> TransformBuffer:
    return TransformBuffer(TransformTable.concat([e.table() for e in edges]))


def two_sample_edge() -> RefEdge:
    return RefEdge("a", "b", np.array([0, 10 * S]), np.array([[0.0, 0, 0], [2.0, 4.0, 6.0]]),
                   np.array([IDENT, yaw(90)]))


# -- interpolation ------------------------------------------------------------------------------
def test_midpoint_interpolates_translation_linearly_and_rotation_by_half_the_angle() -> None:
    result = buffer_of(two_sample_edge()).lookup("a", "b", [5 * S])
    assert result.status.tolist() == [LookupStatus.OK]
    np.testing.assert_allclose(result.translation[0], [1.0, 2.0, 3.0], atol=1e-15)
    assert_same_rotation(result.quat_xyzw, [yaw(45)], atol=1e-15)
    np.testing.assert_allclose(result.hops[0].weight, [0.5])


def test_quarter_point_weight_follows_tf2_ratio() -> None:
    result = buffer_of(two_sample_edge()).lookup("a", "b", [2_500_000_000])
    np.testing.assert_allclose(result.translation[0], [0.5, 1.0, 1.5], atol=1e-15)
    assert_same_rotation(result.quat_xyzw, [yaw(22.5)], atol=1e-15)


def test_slerp_matches_scipy_slerp_on_random_rotations(rng: np.random.Generator) -> None:
    n = 12
    stamps = np.sort(rng.choice(np.arange(0, 100 * S, 1_000_000), size=n, replace=False))
    quats = random_quats(rng, n)
    trans = rng.normal(size=(n, 3))
    buf = buffer_of(RefEdge("w", "r", stamps, trans, quats))
    times = rng.integers(stamps[0], stamps[-1], size=500, endpoint=True)
    result = buf.lookup("w", "r", times)
    assert (result.status == LookupStatus.OK).all()
    expected = Slerp(stamps.astype(float), Rotation.from_quat(quats))(times.astype(float)).as_quat()
    assert_same_rotation(result.quat_xyzw, expected, atol=1e-12)
    lerp = np.stack([np.interp(times, stamps, trans[:, k]) for k in range(3)], axis=1)
    np.testing.assert_allclose(result.translation, lerp, atol=1e-12)


def test_slerp_takes_the_short_way_when_quaternion_signs_differ() -> None:
    # q and -q are the same rotation: tf2 (and scipy) interpolate along the shorter arc.
    q10 = np.array(yaw(10))
    edge = RefEdge("a", "b", np.array([0, 2 * S]), np.zeros((2, 3)), np.array([IDENT, (-q10).tolist()]))
    result = buffer_of(edge).lookup("a", "b", [S])
    assert_same_rotation(result.quat_xyzw, [yaw(5)], atol=1e-15)


def test_exact_stamps_return_the_sample_bit_for_bit_including_first_and_last(rng: np.random.Generator) -> None:
    stamps = np.array([3, 17, 18, 400, 9_000]) * 1_000_000
    quats, trans = random_quats(rng, 5), rng.normal(size=(5, 3))
    table = RefEdge("p", "c", stamps, trans, quats).table()
    result = TransformBuffer(table).lookup("p", "c", stamps)
    assert (result.status == LookupStatus.OK).all()
    np.testing.assert_array_equal(result.translation, trans)
    np.testing.assert_array_equal(result.quat_xyzw, table.quat_xyzw)  # the stored (normalised) sample
    hop = result.hops[0]
    np.testing.assert_array_equal(hop.stamp_before_ns, stamps)
    np.testing.assert_array_equal(hop.stamp_after_ns, stamps)
    np.testing.assert_array_equal(hop.weight, 0.0)
    np.testing.assert_array_equal(hop.gap_ns, 0)


# -- static edges --------------------------------------------------------------------------------
def test_static_edges_are_timeless_and_keep_the_latest_publication() -> None:
    table = TransformTable.concat([
        TransformTable.from_rows("base", "cam", [5 * S], [[9.0, 9.0, 9.0]], [IDENT], is_static=True,
                                 log_time_ns=[5 * S]),
        TransformTable.from_rows("base", "cam", [6 * S], [[0.1, 0.2, 0.3]], [yaw(30)], is_static=True,
                                 log_time_ns=[6 * S]),
    ])
    times = np.array([-10**18, 0, 5 * S, 10**18], dtype=np.int64)
    result = TransformBuffer(table).lookup("base", "cam", times)
    assert (result.status == LookupStatus.OK).all()
    np.testing.assert_allclose(result.translation, np.tile([0.1, 0.2, 0.3], (4, 1)), atol=0)
    assert_same_rotation(result.quat_xyzw, np.tile(yaw(30), (4, 1)), atol=1e-15)
    assert result.hops[0].hop.is_static
    np.testing.assert_array_equal(result.hops[0].gap_ns, 0)


def test_static_only_path_latest_is_ok() -> None:
    buf = buffer_of(RefEdge("base", "cam", np.array([0]), np.array([[1.0, 0, 0]]), np.array([IDENT]), True))
    result = buf.lookup("cam", "base", LATEST)
    assert result.status.tolist() == [LookupStatus.OK]
    np.testing.assert_allclose(result.translation[0], [-1.0, 0.0, 0.0])


# -- chains --------------------------------------------------------------------------------------
def five_edge_chain(rng: np.random.Generator) -> list[RefEdge]:
    """Six frames, five edges: map -> odom (1 Hz) -> base (100 Hz) -> arm (static) -> cam_link (30 Hz) -> cam.

    cam_link -> cam is the static REP-103 optical rotation.
    """
    def dyn(parent: str, child: str, stamps: np.ndarray) -> RefEdge:
        n = stamps.size
        return RefEdge(parent, child, stamps, rng.normal(size=(n, 3)), random_quats(rng, n))

    return [
        dyn("map", "odom", np.arange(0, 11 * S, S)),
        dyn("odom", "base", np.arange(0, 10 * S + 1, 10_000_000) + 3_000_000),
        dyn("arm", "cam_link", np.arange(S // 2, 9 * S, 33_333_333)),
        RefEdge("base", "arm", np.array([0]), np.array([[0.1, 0.0, 0.5]]), np.array([yaw(20)]), True),
        RefEdge("cam_link", "cam", np.array([0]), np.zeros((1, 3)), np.array([[-0.5, 0.5, -0.5, 0.5]]), True),
    ]


def test_chain_of_five_edges_mixing_static_and_dynamic(rng: np.random.Generator) -> None:
    edges = five_edge_chain(rng)
    buf = buffer_of(*edges)
    times = np.concatenate([rng.integers(0, 10 * S, size=200), [0, S // 2, 9 * S, 10 * S, 11 * S, -1]])
    result = buf.lookup("map", "cam", times)
    assert [h.child for h in result.path.hops] == ["cam", "cam_link", "arm", "base", "odom"]
    mats = result.matrix()
    for i, t in enumerate(times.tolist()):
        status, expected = reference_lookup(edges, "map", "cam", t)
        assert result.status[i] == status, t
        if status == 0:
            np.testing.assert_allclose(mats[i], expected, atol=1e-9)
        else:
            assert np.isnan(result.translation[i]).all()
            assert np.isnan(result.quat_xyzw[i]).all()


def test_inverse_lookup_is_the_inverse_matrix(rng: np.random.Generator) -> None:
    edges = five_edge_chain(rng)
    buf = buffer_of(*edges)
    times = rng.integers(S, 9 * S, size=100)
    forward = buf.lookup("map", "cam", times).matrix()
    backward = buf.lookup("cam", "map", times).matrix()
    np.testing.assert_allclose(backward, np.linalg.inv(forward), atol=1e-9)
    # And across a branch: the path goes up to the common ancestor and down again.
    down = buf.lookup("cam", "odom", times).matrix()
    up = buf.lookup("odom", "cam", times).matrix()
    np.testing.assert_allclose(down @ up, np.tile(np.eye(4), (100, 1, 1)), atol=1e-9)


def test_lookup_between_sibling_branches_goes_through_the_common_ancestor(rng: np.random.Generator) -> None:
    edges = [
        RefEdge("base", "left", np.array([0, S]), rng.normal(size=(2, 3)), random_quats(rng, 2)),
        RefEdge("base", "right", np.array([0, 2 * S]), rng.normal(size=(2, 3)), random_quats(rng, 2)),
        RefEdge("world", "base", np.array([5 * S, 6 * S]), rng.normal(size=(2, 3)), random_quats(rng, 2)),
    ]
    result = buffer_of(*edges).lookup("left", "right", [S // 3])
    # world -> base is above the common ancestor: not on the path, so no extrapolation from it.
    assert result.status.tolist() == [LookupStatus.OK]
    assert [(h.child, h.inverse) for h in result.path.hops] == [("right", False), ("left", True)]
    _, expected = reference_lookup(edges, "left", "right", S // 3)
    np.testing.assert_allclose(result.matrix()[0], expected, atol=1e-12)


def test_time_travel_equals_two_plain_lookups_composed_by_hand(rng: np.random.Generator) -> None:
    edges = five_edge_chain(rng)
    buf = buffer_of(*edges)
    t_cam = rng.integers(S, 8 * S, size=50)
    t_world = t_cam + rng.integers(-S // 2, S // 2, size=50)
    travel = buf.lookup("base", t_world, "cam", t_cam, "map")
    world_from_cam = buf.lookup("map", "cam", t_cam).matrix()
    base_from_world = buf.lookup("base", "map", t_world).matrix()
    assert (travel.status == LookupStatus.OK).all()
    np.testing.assert_allclose(travel.matrix(), base_from_world @ world_from_cam, atol=1e-9)
    full = buf.lookup_full("base", t_world, "cam", t_cam, "map")
    np.testing.assert_allclose(full.matrix(), travel.matrix(), atol=0)
    # Same time both sides: the plain lookup.
    same = buf.lookup("base", t_cam, "cam", t_cam, "map")
    np.testing.assert_allclose(same.matrix(), buf.lookup("base", "cam", t_cam).matrix(), atol=1e-9)


def test_time_travel_reports_extrapolation_of_either_side(rng: np.random.Generator) -> None:
    buf = buffer_of(*five_edge_chain(rng))
    good, late = np.array([2 * S, 2 * S]), np.array([2 * S, 20 * S])
    result = buf.lookup("base", late, "cam", good, "map")
    assert result.status.tolist() == [LookupStatus.OK, LookupStatus.EXTRAPOLATED_FUTURE]
    assert np.isnan(result.translation[1]).all()
    result = buf.lookup("base", good, "cam", late, "map")
    assert result.status.tolist() == [LookupStatus.OK, LookupStatus.EXTRAPOLATED_FUTURE]


def test_latest_is_the_latest_common_time_of_the_path(rng: np.random.Generator) -> None:
    edges = five_edge_chain(rng)
    buf = buffer_of(*edges)
    path = buf.path("map", "cam")
    last = min(int(e.stamps[-1]) for e in edges if not e.is_static)
    assert last == int(edges[2].stamps[-1])  # the 30 Hz arm edge stops first
    assert buf.latest_common_time(path) == last
    result = buf.lookup("map", "cam", LATEST)
    assert result.times_ns.tolist() == [last]
    assert result.status.tolist() == [LookupStatus.OK]
    np.testing.assert_allclose(result.matrix()[0], reference_lookup(edges, "map", "cam", last)[1], atol=1e-9)
    # Only the edges on the path count: odom -> map alone ends at 10 s.
    assert buf.lookup("map", "odom", LATEST).times_ns.tolist() == [10 * S]
    assert buf.lookup("odom", "base", LATEST).times_ns.tolist() == [int(edges[1].stamps[-1])]


def test_latest_is_explicit_not_zero(rng: np.random.Generator) -> None:
    buf = buffer_of(*five_edge_chain(rng))
    at_zero = buf.lookup("map", "cam", [0])
    assert at_zero.status.tolist() == [LookupStatus.EXTRAPOLATED_PAST]  # arm edge starts at 0.5 s
    assert repr(LATEST) == "LATEST"
    with pytest.raises(TypeError, match="integer nanoseconds"):
        buf.lookup("map", "cam", [1.5])


# -- extrapolation -------------------------------------------------------------------------------
def test_extrapolation_both_ways_is_reported_and_never_clamped() -> None:
    buf = buffer_of(two_sample_edge())
    result = buf.lookup("a", "b", [-1, 10 * S + 1, 0, 10 * S])
    assert result.status.tolist() == [
        LookupStatus.EXTRAPOLATED_PAST, LookupStatus.EXTRAPOLATED_FUTURE, LookupStatus.OK, LookupStatus.OK
    ]
    assert result.ok.tolist() == [False, False, True, True]
    assert np.isnan(result.translation[:2]).all()
    assert np.isnan(result.quat_xyzw[:2]).all()
    assert np.isfinite(result.translation[2:]).all()
    assert np.isnan(result.matrix()[:2, :3]).all()
    assert result.hops[0].status.tolist() == [PAST, FUTURE, 0, 0]
    # The hop's own samples are not usable there either: NaN, not the clamped end sample.
    assert np.isnan(result.hops[0].translation[:2]).all()
    assert np.isnan(result.hops[0].quat_xyzw[:2]).all()
    assert np.isfinite(result.hops[0].translation[2:]).all()
    with pytest.raises(ExtrapolationError, match="into the past") as err:
        result.raise_for_status()
    assert (err.value.parent, err.value.child, err.value.stamp_ns) == ("a", "b", -1)
    with pytest.raises(ExtrapolationError, match="into the future"):
        buf.lookup("a", "b", [10 * S + 1]).raise_for_status()
    assert buf.can_transform("a", "b", [-1, S]).tolist() == [False, True]


def test_single_sample_dynamic_edge_only_answers_at_its_stamp() -> None:
    buf = buffer_of(RefEdge("a", "b", np.array([S]), np.array([[1.0, 2, 3]]), np.array([IDENT])))
    result = buf.lookup("a", "b", [S - 1, S, S + 1])
    assert result.status.tolist() == [PAST, 0, FUTURE]
    np.testing.assert_array_equal(result.translation[1], [1.0, 2.0, 3.0])


def test_tolerance_gives_nearest_within_the_bound_and_reports_it() -> None:
    buf = buffer_of(two_sample_edge())
    times = [-5, -6, 10 * S + 5, 10 * S + 6, 5 * S]
    result = buf.lookup("a", "b", times, tolerance_ns=5)
    assert result.status.tolist() == [
        LookupStatus.NEAREST, LookupStatus.EXTRAPOLATED_PAST, LookupStatus.NEAREST,
        LookupStatus.EXTRAPOLATED_FUTURE, LookupStatus.OK,
    ]
    assert result.ok.tolist() == [True, False, True, False, True]
    np.testing.assert_array_equal(result.translation[0], [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(result.translation[2], [2.0, 4.0, 6.0])
    assert_same_rotation(result.quat_xyzw[[0, 2]], [IDENT, yaw(90)], atol=1e-15)
    hop = result.hops[0]
    assert hop.stamp_before_ns[0] == hop.stamp_after_ns[0] == 0
    assert hop.stamp_before_ns[2] == hop.stamp_after_ns[2] == 10 * S
    assert hop.gap_ns[0] == -5
    assert hop.gap_ns[2] == 5
    # Without a tolerance the same times extrapolate.
    strict = buf.lookup("a", "b", times)
    assert strict.status.tolist()[:4] == [PAST, PAST, FUTURE, FUTURE]


# -- graph errors --------------------------------------------------------------------------------
def test_unknown_frame_is_no_path_and_connectivity_error() -> None:
    buf = buffer_of(two_sample_edge())
    result = buf.lookup("a", "nowhere", [0, S])
    assert result.status.tolist() == [LookupStatus.NO_PATH] * 2
    assert not result.path.connected
    assert "nowhere" in result.path.problem
    assert np.isnan(result.translation).all()
    with pytest.raises(ConnectivityError, match="'nowhere' does not exist"):
        result.raise_for_status()


def test_two_parents_is_an_error_naming_both() -> None:
    table = TransformTable.concat([
        TransformTable.from_rows("odom", "base_link", [0], [[0.0, 0, 0]], [IDENT], source="/tf"),
        TransformTable.from_rows("map", "base_link", [1], [[0.0, 0, 0]], [IDENT], source="/odom_tf"),
    ])
    with pytest.raises(FrameGraphError, match="base_link") as err:
        TransformBuffer(table)
    assert "'map'" in str(err.value)
    assert "'odom'" in str(err.value)


def test_disconnected_trees_report_no_path_naming_the_roots() -> None:
    buf = buffer_of(
        RefEdge("map", "base", np.array([0]), np.zeros((1, 3)), np.array([IDENT]), True),
        RefEdge("world", "cam", np.array([0]), np.zeros((1, 3)), np.array([IDENT]), True),
    )
    result = buf.lookup("base", "cam", [0])
    assert result.status.tolist() == [LookupStatus.NO_PATH]
    assert "disconnected" in result.path.problem
    assert "'map'" in result.path.problem
    assert "'world'" in result.path.problem
    assert not buf.can_transform("base", "cam", [0]).any()


@pytest.mark.parametrize(
    "pairs",
    [[("a", "b"), ("b", "a")], [("a", "b"), ("b", "c"), ("c", "a")], [("a", "a")]],
    ids=["two", "three", "self"],
)
def test_cycles_are_rejected(pairs: list[tuple[str, str]]) -> None:
    table = TransformTable.concat([
        TransformTable.from_rows(p, c, [0], [[0.0, 0, 0]], [IDENT], is_static=True) for p, c in pairs
    ])
    with pytest.raises(FrameGraphError, match=r"cycle|own parent"):
        TransformBuffer(table)


def test_leading_slash_is_dropped_everywhere() -> None:
    table = TransformTable.from_rows("/map", "/base_link", [0, S], [[0.0, 0, 0], [1.0, 0, 0]], [IDENT, IDENT])
    buf = TransformBuffer(table)
    assert buf.frames == ["base_link", "map"]
    assert buf.parent_of("/base_link") == "map"
    for target, source in [("map", "base_link"), ("/map", "/base_link"), ("map", "/base_link")]:
        result = buf.lookup(target, source, [S // 2])
        assert result.status.tolist() == [LookupStatus.OK]
        np.testing.assert_allclose(result.translation[0], [0.5, 0.0, 0.0])
        assert (result.target, result.source) == ("map", "base_link")


# -- validation ----------------------------------------------------------------------------------
def test_nearly_unit_quaternions_are_normalised() -> None:
    q = np.array(yaw(40)) * (1 + 9e-4)
    table = TransformTable.from_rows("a", "b", [0], [[0.0, 0, 0]], [q])
    np.testing.assert_allclose(np.linalg.norm(table.quat_xyzw, axis=1), 1.0, atol=1e-15)
    result = TransformBuffer(table).lookup("a", "b", [0])
    np.testing.assert_allclose(result.quat_xyzw[0], yaw(40), atol=1e-15)


@pytest.mark.parametrize("scale", [1.0011, 0.998, 2.0, 0.0])
def test_quaternions_far_from_unit_are_rejected(scale: float) -> None:
    q = np.array(yaw(40)) * scale
    with pytest.raises(InvalidTransformError, match="not unit") as err:
        TransformTable.from_rows("a", "b", [0, 7], [[0.0, 0, 0]] * 2, [IDENT, q], source="/tf")
    assert (err.value.parent, err.value.child, err.value.stamp_ns, err.value.source) == ("a", "b", 7, "/tf")


@pytest.mark.parametrize("where", ["translation", "quat"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_or_inf_is_rejected_naming_edge_and_stamp(where: str, bad: float) -> None:
    trans = np.zeros((3, 3))
    quats = np.tile(IDENT, (3, 1))
    (trans if where == "translation" else quats)[1, 0] = bad
    with pytest.raises(InvalidTransformError, match="NaN or Inf") as err:
        TransformTable.from_rows("/odom", "base", [10, 20, 30], trans, quats)
    assert "odom -> base" in str(err.value)
    assert "20 ns" in str(err.value)
    assert (err.value.parent, err.value.child, err.value.stamp_ns) == ("odom", "base", 20)


# -- per-hop samples -----------------------------------------------------------------------------
def test_per_hop_sample_stamps_weights_and_gaps(rng: np.random.Generator) -> None:
    edges = five_edge_chain(rng)
    buf = buffer_of(*edges)
    t = 2 * S + 250_000_000  # odom->base samples every 10 ms from 3 ms; map->odom every 1 s
    result = buf.lookup("map", "cam", [t])
    by_child = {h.hop.child: h for h in result.hops}
    assert set(by_child) == {"cam", "cam_link", "arm", "base", "odom"}
    odom = by_child["odom"]
    assert (odom.stamp_before_ns[0], odom.stamp_after_ns[0]) == (2 * S, 3 * S)
    assert odom.weight[0] == pytest.approx(0.25)
    assert odom.gap_ns[0] == 250_000_000
    base = by_child["base"]
    assert (base.stamp_before_ns[0], base.stamp_after_ns[0]) == (2_243_000_000, 2_253_000_000)
    assert base.weight[0] == pytest.approx(0.7)
    assert base.gap_ns[0] == -3_000_000  # nearest sample is the later one
    arm = by_child["cam_link"]
    k = (t - S // 2) // 33_333_333
    lo = S // 2 + k * 33_333_333
    assert (arm.stamp_before_ns[0], arm.stamp_after_ns[0]) == (lo, lo + 33_333_333)
    assert arm.weight[0] == pytest.approx((t - lo) / 33_333_333)
    for static in ("cam", "arm"):
        hop = by_child[static]
        assert hop.hop.is_static
        assert hop.weight[0] == 0.0
        assert hop.gap_ns[0] == 0
        assert hop.stamp_before_ns[0] == hop.stamp_after_ns[0] == 0
    # The per-hop transforms are the edges' own T_parent_child at t.
    for hop in result.hops:
        edge = next(e for e in edges if e.child == hop.hop.child)
        np.testing.assert_allclose(
            matrix(hop.translation[0], hop.quat_xyzw[0]),
            reference_lookup([edge], edge.parent, edge.child, t)[1], atol=1e-12,
        )


def test_per_hop_samples_are_the_same_in_chunked_lookups(rng: np.random.Generator) -> None:
    # More times than one internal chunk: results must not depend on how the times are split.
    edges = five_edge_chain(rng)
    buf = buffer_of(*edges)
    times = rng.integers(-S, 12 * S, size=150_000)
    big = buf.lookup("map", "cam", times)
    for sl in (slice(0, 1000), slice(70_000, 71_000), slice(149_000, 150_000)):
        small = buf.lookup("map", "cam", times[sl])
        np.testing.assert_array_equal(big.status[sl], small.status)
        np.testing.assert_array_equal(big.translation[sl], small.translation)
        np.testing.assert_array_equal(big.quat_xyzw[sl], small.quat_xyzw)
        for hb, hs in zip(big.hops, small.hops, strict=True):
            np.testing.assert_array_equal(hb.stamp_before_ns[sl], hs.stamp_before_ns)
            np.testing.assert_array_equal(hb.stamp_after_ns[sl], hs.stamp_after_ns)
            np.testing.assert_array_equal(hb.weight[sl], hs.weight)
            np.testing.assert_array_equal(hb.status[sl], hs.status)


# -- stamp layouts the index must get right -------------------------------------------------------
EPOCH = 1_763_800_000 * S  # unix time in ns: beyond float64's exact integers


@pytest.mark.parametrize("layout", ["uniform", "jittered", "bursty", "two"])
def test_sample_index_is_exact_for_every_stamp_layout(rng: np.random.Generator, layout: str) -> None:
    if layout == "uniform":
        stamps = EPOCH + np.arange(500) * 10_000_000
    elif layout == "jittered":
        stamps = EPOCH + np.arange(500) * 10_000_000 + rng.integers(-4_000_000, 4_000_000, 500)
    elif layout == "bursty":  # bursts of samples 1 ns apart, long gaps between them
        stamps = EPOCH + np.concatenate([b * S + np.arange(40) for b in range(12)])
    else:
        stamps = EPOCH + np.array([0, 1])
    stamps = np.unique(stamps)
    n = stamps.size
    edge = RefEdge("a", "b", stamps, rng.normal(size=(n, 3)), random_quats(rng, n))
    buf = buffer_of(edge)
    pick = rng.choice(n, size=min(n, 60), replace=False)
    times = np.concatenate([
        stamps[pick], stamps[pick] - 1, stamps[pick] + 1, [stamps[0], stamps[-1], stamps[0] - 1, stamps[-1] + 1],
        rng.integers(stamps[0], stamps[-1], size=60, endpoint=True),
    ])
    result = buf.lookup("a", "b", times)
    hop = result.hops[0]
    for i, t in enumerate(times.tolist()):
        status, expected = reference_lookup([edge], "a", "b", t)
        assert result.status[i] == status, t
        if status != 0:
            continue
        np.testing.assert_allclose(result.matrix()[i], expected, atol=1e-9)
        j = int(np.searchsorted(stamps, t, side="right")) - 1
        assert hop.stamp_before_ns[i] == stamps[j]
        assert hop.stamp_after_ns[i] == (stamps[j] if stamps[j] == t else stamps[j + 1])


def test_extreme_times_extrapolate_without_overflow() -> None:
    buf = buffer_of(two_sample_edge())
    big = np.iinfo(np.int64)
    times = np.array([big.min, big.min + 1, -1, big.max - 1, big.max], dtype=np.int64)
    result = buf.lookup("a", "b", times)
    assert result.status.tolist() == [PAST, PAST, PAST, FUTURE, FUTURE]
    assert np.isnan(result.translation).all()
    hop = result.hops[0]
    assert hop.stamp_before_ns.tolist() == [0, 0, 0, 10 * S, 10 * S]
    assert hop.stamp_after_ns.tolist() == hop.stamp_before_ns.tolist()
    np.testing.assert_array_equal(hop.weight, 0.0)
