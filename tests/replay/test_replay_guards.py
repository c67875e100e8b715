"""The hop-by-hop replay: every guard, the accounting, depth sampling and the hop records."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from framechain.catalogue import HopName, RejectReason
from framechain.config.chain import ChainFrames
from framechain.replay import REPLAYED, ReplayOptions, replay, sample_depth
from framechain.timeline import CameraTable, DepthFrameTable, ObservationTable, Timeline, TransformTable

S = 1_000_000_000
MS = 1_000_000
FRAMES = ChainFrames(camera="cam", body="base", world="map")
IDENT = [0.0, 0.0, 0.0, 1.0]
H, W = 480, 640


def observations(rows: list[tuple[int, float, float, float]]) -> ObservationTable:
    """(stamp_ns, u, v, depth_m) per observation; obs_id = 100 + index."""
    n = len(rows)
    stamps, u, v, depth = (np.array(c) for c in zip(*rows, strict=True))
    return ObservationTable(
        obs_id=np.arange(100, 100 + n), stamp_ns=stamps.astype(np.int64), log_time_ns=stamps.astype(np.int64),
        camera_frame=np.full(n, "cam"), u=u.astype(float), v=v.astype(float), depth_m=depth.astype(float),
        label=np.full(n, "cup"), score=np.full(n, 0.9), source=np.full(n, "/detections"),
    )


def transforms(*, with_camera: bool = True) -> TransformTable:
    stamps = np.arange(0, 11) * S  # body pose at 1 Hz, moving 1 m/s along x
    parts = [TransformTable.from_rows("map", "base", stamps, np.stack([stamps / S, np.zeros(11), np.zeros(11)], 1),
                                      np.tile(IDENT, (11, 1)), source="/tf")]
    if with_camera:
        parts.append(TransformTable.from_rows("base", "cam", [0], [[0.3, 0.0, 0.8]], [IDENT], is_static=True))
    return TransformTable.concat(parts)


def camera() -> CameraTable:
    return CameraTable.from_intrinsics("cam", fx=600, fy=600, cx=320, cy=240, width=W, height=H)


def depth_image(fill: float = np.nan) -> np.ndarray:
    return np.full((H, W), fill, dtype=np.float32)


# One observation per guard (and two that pass).
CASES: list[tuple[str, tuple[int, float, float, float]]] = [
    ("replayed", (2 * S, 380.0, 210.0, 2.0)),
    ("outside_image", (2 * S, 700.0, 210.0, 2.0)),
    ("outside_image", (2 * S, 320.0, -3.0, 2.0)),
    ("no_depth", (2 * S, 320.0, 240.0, np.nan)),
    ("depth_invalid", (2 * S, 320.0, 240.0, 0.0)),
    ("depth_invalid", (2 * S, 320.0, 240.0, -1.5)),
    ("depth_invalid", (2 * S, 320.0, 240.0, np.inf)),  # given, but not finite (NaN alone means "not given")
    ("extrapolation", (20 * S, 320.0, 240.0, 2.0)),
    ("extrapolation", (-S, 320.0, 240.0, 2.0)),
    ("replayed", (2 * S + 500 * MS, 320.0, 240.0, 1.0)),  # stale: 0.5 s from the nearest pose sample
]


def test_every_guard_and_the_totals_reconcile() -> None:
    obs = observations([row for _, row in CASES])
    timeline = Timeline(transforms=transforms(), cameras=camera(), observations=obs)
    result = replay(timeline, FRAMES, latency_budget_s=0.02)
    assert result.status.tolist() == [reason for reason, _ in CASES]
    counts = result.counts()
    assert counts == {
        "total": 10, "replayed": 2, "stale": 1,
        "rejected": {"outside_image": 2, "no_depth": 1, "depth_invalid": 3, "extrapolation": 2},
    }
    rejected = counts["rejected"]
    assert isinstance(rejected, dict)
    assert counts["replayed"] + sum(rejected.values()) == counts["total"] == len(obs)
    assert set(rejected) <= {r.value for r in RejectReason}
    assert result.stale.tolist() == [False] * 9 + [True]
    # Replayed rows carry points; rejected rows carry NaN, never a made-up point.
    ok = result.replayed
    assert np.isfinite(result.p_world[ok]).all()
    assert np.isnan(result.p_world[~ok]).all()
    assert np.isnan(result.p_cam[~ok]).all()
    np.testing.assert_allclose(result.p_world[0], [2.0 + 0.5, -0.1, 2.8], atol=1e-12)
    # The stale observation is still replayed, with the interpolated pose.
    np.testing.assert_allclose(result.p_world[9], [2.5 + 0.3, 0.0, 1.8], atol=1e-12)


def test_the_first_failing_guard_names_the_reason() -> None:
    # Outside the image and no depth and extrapolated: the hop-1 guard comes first.
    obs = observations([(20 * S, 900.0, 240.0, np.nan)])
    result = replay(Timeline(transforms=transforms(), cameras=camera(), observations=obs), FRAMES)
    assert result.status.tolist() == [RejectReason.OUTSIDE_IMAGE.value]


def test_no_camera_info_rejects_everything() -> None:
    obs = observations([(2 * S, 320.0, 240.0, 2.0), (3 * S, 10.0, 10.0, 1.0)])
    other = CameraTable.from_intrinsics("other_cam", fx=600, fy=600, cx=320, cy=240, width=W, height=H)
    result = replay(Timeline(transforms=transforms(), cameras=other, observations=obs), FRAMES)
    assert result.counts() == {"total": 2, "replayed": 0, "stale": 0, "rejected": {"no_camera_info": 2}}


def test_missing_edge_rejects_and_is_counted() -> None:
    obs = observations([(2 * S, 320.0, 240.0, 2.0), (3 * S, 10.0, 10.0, 1.0)])
    timeline = Timeline(transforms=transforms(with_camera=False), cameras=camera(), observations=obs)
    result = replay(timeline, FRAMES)
    assert result.counts()["rejected"] == {"missing_edge": 2}
    assert not result.body_from_cam.path.connected
    unknown_world = replay(Timeline(transforms=transforms(), cameras=camera(), observations=obs),
                           ChainFrames(camera="cam", body="base", world="earth"))
    assert unknown_world.counts()["rejected"] == {"missing_edge": 2}


def test_a_tolerance_replays_just_outside_the_span_and_marks_it_stale() -> None:
    obs = observations([(10 * S + 3 * MS, 320.0, 240.0, 2.0)])
    timeline = Timeline(transforms=transforms(), cameras=camera(), observations=obs)
    assert replay(timeline, FRAMES).status.tolist() == ["extrapolation"]
    result = replay(timeline, FRAMES, options=ReplayOptions(tolerance_ns=5 * MS), latency_budget_s=1.0)
    assert result.status.tolist() == [REPLAYED]
    assert result.stale.tolist() == [True]


# -- depth from depth frames ---------------------------------------------------------------------
def depth_timeline(images: list[np.ndarray], stamps: list[int], obs_rows: list[tuple[int, float, float, float]]
                   ) -> Timeline:
    frames = DepthFrameTable.from_arrays("cam", stamps, np.stack(images))
    return Timeline(transforms=transforms(), cameras=camera(), observations=observations(obs_rows),
                    depth_frames=frames)


def test_depth_is_the_window_median_ignoring_zeros_and_nan() -> None:
    image = depth_image()
    window = np.array([
        [1.0, 1.1, 0.0, np.nan, 1.2],
        [1.3, 0.0, 0.0, 5.0, np.nan],
        [1.4, np.nan, 1.5, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.0, 0.0],
        [np.nan, np.nan, 9.0, 1.6, -2.0],
    ], dtype=np.float32)
    image[98:103, 198:203] = window
    valid = [1.0, 1.1, 1.2, 1.3, 5.0, 1.4, 1.5, 9.0, 1.6]  # finite and > 0
    timeline = depth_timeline([image], [2 * S], [(2 * S, 200.0, 100.0, np.nan), (2 * S, 200.4, 99.6, np.nan)])
    result = replay(timeline, FRAMES)
    assert result.status.tolist() == [REPLAYED, REPLAYED]
    np.testing.assert_allclose(result.depth_m, np.median(np.float32(valid)), rtol=1e-7)
    assert result.depth_stamp_ns.tolist() == [2 * S, 2 * S]
    np.testing.assert_allclose(result.p_cam[0, 2], result.depth_m[0])


def test_depth_window_all_invalid_is_depth_invalid_and_no_frame_is_no_depth() -> None:
    image = depth_image(0.0)
    image[:, 600:] = np.nan
    rows = [(2 * S, 100.0, 100.0, np.nan), (2 * S, 630.0, 100.0, np.nan), (4 * S, 100.0, 100.0, np.nan)]
    result = replay(depth_timeline([image], [2 * S], rows), FRAMES)
    assert result.status.tolist() == ["depth_invalid", "depth_invalid", "no_depth"]


def test_depth_frame_stamped_at_zero_is_a_frame() -> None:
    # A log whose clock starts at 0: the depth frame at stamp 0 exists even though its stamp is 0.
    image = depth_image(0.0)
    rows = [(0, 100.0, 100.0, np.nan), (10 * MS, 100.0, 100.0, np.nan)]
    result = replay(depth_timeline([image], [0], rows), FRAMES)
    assert result.status.tolist() == ["depth_invalid", "depth_invalid"]
    good = depth_image(1.25)
    result = replay(depth_timeline([good], [0], rows), FRAMES, latency_budget_s=0.005)
    assert result.status.tolist() == [REPLAYED, REPLAYED]
    pix = result.hops.take(result.hops.hop == HopName.PIXEL_TO_CAMERA.value)
    assert pix.sample_before_ns.tolist() == [0, 0]
    assert pix.gap_ns.tolist() == [0, 10 * MS]
    assert pix.stale.tolist() == [False, True]


def test_nearest_depth_frame_in_time_within_the_gap() -> None:
    frames = [depth_image(1.0), depth_image(2.0), depth_image(3.0)]
    stamps = [2 * S - 30 * MS, 2 * S + 10 * MS, 2 * S + 200 * MS]
    rows = [(2 * S, 100.0, 100.0, np.nan), (2 * S - 25 * MS, 5.0, 5.0, np.nan),
            (2 * S + 120 * MS, 5.0, 5.0, np.nan), (2 * S + 106 * MS, 5.0, 5.0, np.nan)]
    result = replay(depth_timeline(frames, stamps, rows), FRAMES, options=ReplayOptions(max_depth_gap_ns=70 * MS))
    assert result.depth_m.tolist()[:2] == [2.0, 1.0]
    assert result.depth_stamp_ns.tolist()[:2] == [2 * S + 10 * MS, 2 * S - 30 * MS]
    assert result.status.tolist() == [REPLAYED, REPLAYED, "no_depth", "no_depth"]  # 80 ms and 94 ms away
    wider = replay(depth_timeline(frames, stamps, rows), FRAMES, options=ReplayOptions(max_depth_gap_ns=80 * MS))
    assert wider.status.tolist() == [REPLAYED, REPLAYED, REPLAYED, "no_depth"]
    assert wider.depth_m.tolist()[2] == 3.0


def test_depth_window_at_the_image_border_uses_only_pixels_inside() -> None:
    # At a corner a 5x5 window holds 3x3 pixels inside the image; none may count twice.
    image = depth_image(10.0)
    image[0, 0] = 1.0
    image[0, 1] = image[1, 0] = 2.0
    image[1, 1] = image[0, 2] = image[2, 0] = 3.0
    sampled = sample_depth(DepthFrameTable.from_arrays("cam", [0], image[None]), "cam", np.array([0]),
                           np.array([0.0]), np.array([0.0]), max_gap_ns=0)
    inside = [1.0, 2.0, 2.0, 3.0, 3.0, 3.0, 10.0, 10.0, 10.0]
    assert sampled.depth_m.tolist() == [np.median(inside)]
    assert sampled.frame_index.tolist() == [0]


# -- hop records ---------------------------------------------------------------------------------
def test_hop_records_three_rows_per_observation_with_frames_samples_and_gaps() -> None:
    rows = [(2 * S + 250 * MS, 380.0, 210.0, 2.0), (7 * S, 320.0, 240.0, 1.0), (30 * S, 320.0, 240.0, 1.0)]
    timeline = Timeline(transforms=transforms(), cameras=camera(), observations=observations(rows))
    result = replay(timeline, FRAMES, latency_budget_s=0.1)
    hops = result.hops
    assert len(hops) == 3 * 3
    for hop, (src, dst) in zip(HopName, [("pixel", "cam"), ("cam", "base"), ("base", "map")], strict=True):
        sel = hops.take(hops.hop == hop.value)
        assert sel.obs_id.tolist() == [100, 101, 102]
        assert sel.from_frame.tolist() == [src] * 3
        assert sel.to_frame.tolist() == [dst] * 3
        assert sel.stamp_ns.tolist() == [r[0] for r in rows]
        assert sel.status.tolist() == [REPLAYED, REPLAYED, "extrapolation"]
    world = hops.take(hops.hop == HopName.BODY_TO_WORLD.value)
    assert world.sample_before_ns.tolist()[:2] == [2 * S, 7 * S]
    assert world.sample_after_ns.tolist()[:2] == [3 * S, 7 * S]
    assert world.gap_ns.tolist()[:2] == [250 * MS, 0]
    assert world.stale.tolist()[:2] == [True, False]
    np.testing.assert_allclose(world.translation[0], [2.25, 0.0, 0.0])
    np.testing.assert_allclose(world.input_xyz[:2], result.p_body[:2])
    np.testing.assert_allclose(world.output_xyz[:2], result.p_world[:2])
    body = hops.take(hops.hop == HopName.CAMERA_TO_BODY.value)
    assert body.gap_ns.tolist() == [0, 0, 0]
    assert not body.stale.any()
    np.testing.assert_allclose(body.translation, np.tile([0.3, 0.0, 0.8], (3, 1)))
    np.testing.assert_allclose(body.input_xyz[:2], result.p_cam[:2])
    pix = hops.take(hops.hop == HopName.PIXEL_TO_CAMERA.value)
    np.testing.assert_allclose(pix.input_xyz, [[380.0, 210.0, 2.0], [320.0, 240.0, 1.0], [320.0, 240.0, 1.0]])
    np.testing.assert_allclose(pix.output_xyz[0], [0.2, -0.1, 2.0], atol=1e-12)
    assert pix.gap_ns.tolist() == [0, 0, 0]
    assert result.counts()["stale"] == 1


def test_hop_samples_keep_every_edge_and_the_gap_to_each_sample() -> None:
    """map -> odom at 1 Hz and odom -> base at 10 Hz: both edges' samples and gaps, hand-worked."""
    stamps_odom = np.arange(0, 11) * S
    stamps_base = np.arange(0, 101) * 100 * MS
    tf = TransformTable.concat([
        TransformTable.from_rows("map", "odom", stamps_odom, np.zeros((11, 3)), np.tile(IDENT, (11, 1))),
        TransformTable.from_rows("odom", "base", stamps_base, np.zeros((101, 3)), np.tile(IDENT, (101, 1))),
        TransformTable.from_rows("base", "cam", [0], [[0.3, 0.0, 0.8]], [IDENT], is_static=True),
    ])
    rows = [(2 * S + 250 * MS, 320.0, 240.0, 1.0), (5 * S + 730 * MS, 320.0, 240.0, 1.0)]
    result = replay(Timeline(transforms=tf, cameras=camera(), observations=observations(rows)), FRAMES)
    samples = result.samples
    world = samples.take(samples.hop == HopName.BODY_TO_WORLD.value)
    by_edge = {(p, c): world.take((world.parent == p) & (world.child == c)) for p, c in {("map", "odom"),
                                                                                         ("odom", "base")}}
    odom, base = by_edge[("map", "odom")], by_edge[("odom", "base")]
    assert odom.obs_id.tolist() == [100, 101]
    assert odom.sample_before_ns.tolist() == [2 * S, 5 * S]
    assert odom.sample_after_ns.tolist() == [3 * S, 6 * S]
    assert odom.gap_before_ns.tolist() == [250 * MS, 730 * MS]
    assert odom.gap_after_ns.tolist() == [-750 * MS, -270 * MS]
    np.testing.assert_allclose(odom.weight, [0.25, 0.73])
    assert base.sample_before_ns.tolist() == [2200 * MS, 5700 * MS]
    assert base.sample_after_ns.tolist() == [2300 * MS, 5800 * MS]
    assert base.gap_before_ns.tolist() == [50 * MS, 30 * MS]
    # The hop record keeps the stalest edge only: the 1 Hz odometry, 270 ms for the second.
    hop = result.hops.take(result.hops.hop == HopName.BODY_TO_WORLD.value)
    assert hop.gap_ns.tolist() == [250 * MS, -270 * MS]
    mount = samples.take(samples.hop == HopName.CAMERA_TO_BODY.value)
    assert mount.static.all()
    assert (mount.parent.tolist(), mount.child.tolist()) == (["base", "base"], ["cam", "cam"])
    assert mount.gap_before_ns.tolist() == [0, 0]
    assert set(samples.status.tolist()) == {REPLAYED}


def test_pose_offset_shifts_the_lookup_but_gaps_stay_against_the_observation() -> None:
    rows = [(2 * S, 320.0, 240.0, 1.0)]
    timeline = Timeline(transforms=transforms(), cameras=camera(), observations=observations(rows))
    result = replay(timeline, FRAMES, options=ReplayOptions(pose_offset_ns=-400 * MS))
    np.testing.assert_allclose(result.p_world[0], [1.6 + 0.3, 0.0, 1.8], atol=1e-12)
    world = result.hops.take(result.hops.hop == HopName.BODY_TO_WORLD.value)
    assert world.sample_before_ns.tolist() == [S]
    assert world.sample_after_ns.tolist() == [2 * S]
    assert world.gap_ns.tolist() == [0]


@pytest.mark.parametrize("n", [0, 1])
def test_tiny_inputs(n: int) -> None:
    rows = [(2 * S, 320.0, 240.0, 1.0)][:n]
    obs = observations(rows) if rows else ObservationTable.empty()
    result = replay(Timeline(transforms=transforms(), cameras=camera(), observations=obs), FRAMES)
    assert result.counts()["total"] == n
    assert len(result.hops) == 3 * n


def test_observations_of_another_camera_are_rejected_and_counted() -> None:
    """A second camera with its own CameraInfo: its detections are not replayed through this chain."""
    import dataclasses

    from framechain.config.chain import ChainFrames
    from framechain.replay import replay
    from framechain.timeline import CameraTable, ObservationTable, Timeline, TransformTable

    cams = CameraTable.concat([
        CameraTable.from_intrinsics("front_optical", fx=500, fy=500, cx=320, cy=240, width=640, height=480),
        CameraTable.from_intrinsics("rear_optical", fx=500, fy=500, cx=320, cy=240, width=640, height=480),
    ])
    tf = TransformTable.concat([
        TransformTable.from_rows("map", "base_link", [0], [[0.0, 0.0, 0.0]], [[0, 0, 0, 1.0]], is_static=True),
        *[TransformTable.from_rows("base_link", cam, [0], [[0.0, 0.0, 1.0]], [[0, 0, 0, 1.0]], is_static=True)
          for cam in ("front_optical", "rear_optical")],
    ])
    n = 5
    frames = np.array(["front_optical", "rear_optical", "rear_optical", "", "front_optical"])
    obs = ObservationTable(obs_id=np.arange(n), stamp_ns=np.arange(n), log_time_ns=np.arange(n), camera_frame=frames,
                           u=np.full(n, 320.0), v=np.full(n, 240.0), depth_m=np.full(n, 2.0), label=np.full(n, ""),
                           score=np.ones(n), source=np.full(n, ""))
    result = replay(Timeline(transforms=tf, cameras=cams, observations=obs),
                    ChainFrames(camera="front_optical", body="base_link", world="map"))
    assert result.counts() == {"total": 5, "replayed": 3, "rejected": {"other_camera": 2}, "stale": 0}
    assert list(result.status) == ["replayed", "other_camera", "other_camera", "replayed", "replayed"]
    # A frame name the log has no camera for is read as this chain's camera (a naming mismatch, not a camera).
    renamed = dataclasses.replace(obs, camera_frame=np.full(n, "front_camera_link"))
    assert replay(Timeline(transforms=tf, cameras=cams, observations=renamed),
                  ChainFrames(camera="front_optical", body="base_link", world="map")).counts()["replayed"] == 5


def test_saved_and_reloaded_transforms_are_bit_identical(tmp_path: Path) -> None:
    from framechain.timeline import Timeline, TransformTable

    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    table = TransformTable.from_rows("a", "b", np.arange(50), rng.normal(size=(50, 3)), q)
    Timeline(transforms=table).save(tmp_path / "t")
    assert Timeline.load(tmp_path / "t").transforms.equals(table)
