"""The same scene written to .mcap (ROS 2), .mcap (ROS 1), .bag, ROS 2 sqlite3 and ROS 2 mcap
storage must give equal Timelines; compressed variants and bare storage files too."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from framechain.adapters import CONTAINERS, canonical_order, open_log, scan_log, write_log
from framechain.replay import sample_depth
from framechain.timeline import Timeline
from tests.helpers.adapter_scene import CHAIN, T0

TABLES = ("transforms", "cameras", "observations", "joint_states", "points", "depth_frames")


def assert_same(got: Timeline, expected: Timeline, *, depth_atol: float = 1e-6) -> None:
    exp = canonical_order(expected)
    for name in TABLES:
        a, b = getattr(got, name), getattr(exp, name)
        assert len(a) == len(b), name
        for col in a.COLUMNS:
            x, y = getattr(a, col), getattr(b, col)
            if x.dtype.kind == "f":
                np.testing.assert_array_equal(x, y, err_msg=f"{name}.{col}")
            else:
                assert np.array_equal(x, y), f"{name}.{col}: {x[:3]} != {y[:3]}"
    for i in range(len(exp.depth_frames)):
        np.testing.assert_allclose(got.depth_frames.load(i), exp.depth_frames.load(i), rtol=0, atol=depth_atol)


@pytest.mark.parametrize("container", CONTAINERS)
def test_every_container_gives_the_same_timeline(container: str, written: dict[str, Path], scene: Timeline) -> None:
    loaded = open_log(written[container], CHAIN)
    assert_same(loaded.timeline, scene)
    # The only note: the scene's known depths travel in the detections' hypothesis pose, and the reader says so.
    n_known = int(np.isfinite(scene.observations.depth_m).sum())
    assert loaded.info.notes == (
        f"topic /detections: {n_known} detections carry a depth in results[0].pose.pose.position.z; it is used as the "
        "z-depth in the camera frame instead of sampling the depth image",
    )
    assert loaded.timeline.metadata["source_path"] == str(written[container])


@pytest.mark.parametrize("container", CONTAINERS)
def test_scan_counts_messages_per_topic(container: str, written: dict[str, Path]) -> None:
    info = scan_log(written[container])
    counts = {t.name: t.count for t in info.topics}
    # 40 odom samples and 10 map->odom samples at distinct log times; both static edges in one message.
    assert counts == {
        "/tf": 50, "/tf_static": 1, "/camera/color/camera_info": 1, "/detections": 6,
        "/camera/depth/image_rect_raw": 3, "/joint_states": 8, "/debug/point_world": 2, "/grasp_target": 1,
        "/mocap/target": 1,
    }
    assert info.format == {"mcap-ros2": "mcap", "mcap-ros1": "mcap", "rosbag1": "rosbag1"}.get(container, "rosbag2")
    assert info.start_ns == T0
    types = {t.name: t.msgtype.replace("/msg/", "/") for t in info.topics}
    assert types["/mocap/target"] == "geometry_msgs/PoseStamped"  # every row has a rotation
    assert types["/grasp_target"] == "geometry_msgs/PointStamped"
    assert types["/detections"] == "vision_msgs/Detection2DArray"


@pytest.mark.parametrize(("container", "compression"), [
    ("rosbag1", "bz2"), ("rosbag1", "lz4"), ("rosbag2-sqlite", "zstd-file"), ("rosbag2-sqlite", "zstd-message"),
    ("rosbag2-mcap", "zstd-message"),
])
def test_compressed_containers(container: str, compression: str, scene: Timeline, tmp_path: Path) -> None:
    path = write_log(scene, tmp_path / ("c.bag" if container == "rosbag1" else "c"), container=container,
                     chain=CHAIN, compression=compression)
    loaded = open_log(path, CHAIN)
    assert_same(loaded.timeline, scene)
    if container != "rosbag1":
        assert "zstd" in loaded.info.container


@pytest.mark.parametrize("container", ["rosbag2-sqlite", "rosbag2-mcap"])
def test_bare_storage_file_without_metadata(container: str, written: dict[str, Path], scene: Timeline) -> None:
    storage = next(p for p in written[container].iterdir() if p.suffix in (".db3", ".mcap"))
    assert_same(open_log(storage, CHAIN).timeline, scene)


def test_32fc1_depth_is_exact(scene: Timeline, tmp_path: Path) -> None:
    path = write_log(scene, tmp_path / "f.mcap", container="mcap-ros2", chain=CHAIN, depth_encoding="32FC1")
    got = open_log(path, CHAIN).timeline.depth_frames
    assert got.encoding.tolist() == ["32FC1"] * 3
    for i in range(3):
        assert np.array_equal(got.load(i), scene.depth_frames.load(i))


def test_16uc1_quantises_to_millimetres(scene: Timeline, tmp_path: Path) -> None:
    import dataclasses

    image = np.full((4, 5), 1.2345678, dtype=np.float32)
    image[0, 0] = np.nan
    depth = dataclasses.replace(scene.depth_frames.take([0]), width=np.array([5]), height=np.array([4]),
                                loader=lambda i: image)
    path = write_log(Timeline(depth_frames=depth), tmp_path / "q.bag", container="rosbag1", chain=CHAIN)
    got = open_log(path).timeline.depth_frames.load(0)
    assert got[1, 1] == np.float32(1235 * np.float32(0.001))
    assert got[0, 0] == 0.0  # NaN (no depth) is written as 0, the ROS convention


def test_depth_frames_are_decoded_lazily_and_only_where_needed(
    written: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    from framechain.adapters import api

    calls: list[tuple[str, int]] = []
    real = api._fetcher

    def counting(fmt: str, target: Path, *more: object):  # type: ignore[no-untyped-def]
        inner = real(fmt, target, *more)

        def fetch(topic: str, log_ns: int, ordinal: int) -> object:
            calls.append((topic, log_ns))
            return inner(topic, log_ns, ordinal)

        return fetch

    monkeypatch.setattr(api, "_fetcher", counting)
    tl = open_log(written["rosbag2-mcap"], CHAIN).timeline
    assert calls == []  # reading the log decodes no pixels
    obs = tl.observations
    one = np.array([1])
    res = sample_depth(tl.depth_frames, "camera_optical_frame", obs.stamp_ns[one], obs.u[one], obs.v[one],
                       max_gap_ns=10**9)
    assert len(calls) == 1
    # The plane of the scene at that pixel: 1 + 0.02 u + 0.01 v (+0.1 per frame), read back in mm.
    k = int(res.frame_index[0])
    expected = 1.0 + 0.02 * np.rint(obs.u[1]) + 0.01 * np.rint(obs.v[1]) + 0.1 * k
    assert res.depth_m[0] == pytest.approx(expected, abs=1.5e-3)


def test_only_the_chain_topics_are_decoded(written: dict[str, Path]) -> None:
    from framechain.config.chain import ChainConfig

    chain = ChainConfig.from_dict({"topics": {"camera_info": "/camera/color/camera_info"}})
    loaded = open_log(written["mcap-ros2"], chain)
    assert set(loaded.decoded_topics) == {"/tf", "/tf_static", "/camera/color/camera_info", "/joint_states"}
    assert len(loaded.timeline.observations) == 0
    assert len(loaded.timeline.depth_frames) == 0
    assert len(loaded.timeline.transforms) == 52


def test_write_refuses_to_overwrite_and_unknown_container(scene: Timeline, tmp_path: Path) -> None:
    from framechain.adapters import AdapterError

    (tmp_path / "x.mcap").write_bytes(b"")
    with pytest.raises(AdapterError, match="exists already"):
        write_log(scene, tmp_path / "x.mcap", container="mcap-ros2", chain=CHAIN)
    with pytest.raises(AdapterError, match="unknown container"):
        write_log(scene, tmp_path / "y", container="hdf5", chain=CHAIN)


@pytest.mark.parametrize("container", ["mcap-ros2", "rosbag1", "rosbag2-sqlite"])
def test_processes_forked_after_a_frame_was_read_read_their_own(written: dict[str, Path], container: str,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """The reader kept open for lazy frames shares its file position with any process forked after it opened (a
    camera measured in each): every child opens its own, and fetches exactly what the parent fetched."""
    import os

    from framechain.adapters import api
    from framechain.vision.threads import forks, map_forked

    if not forks():
        pytest.skip("map_forked forks on Linux only")
    fetched: list[tuple[api._KeptOpenFetcher, tuple[str, int, int], object]] = []
    fetch = api._KeptOpenFetcher.__call__

    def noting(self: api._KeptOpenFetcher, *args: object) -> object:
        got = fetch(self, *args)  # type: ignore[arg-type]
        fetched.append((self, args, got))  # type: ignore[arg-type]
        return got

    monkeypatch.setattr(api._KeptOpenFetcher, "__call__", noting)
    depth = open_log(written[container], CHAIN).timeline.depth_frames
    for i in range(len(depth)):
        depth.load(i)
    calls = list(fetched)
    assert calls
    assert all(fetcher._log is not None for fetcher, _args, _got in calls)  # the parent's readers are open

    def fetch_all(order: int) -> tuple[bool, list[str]]:
        fresh = all(fetcher._log is None for fetcher, _args, _got in calls)  # none inherited
        for _round in range(50):
            for fetcher, args, expected in (calls if order % 2 else calls[::-1]):
                assert repr(fetch(fetcher, *args)) == repr(expected), f"process {os.getpid()} read other bytes"
        return fresh, [repr(fetch(fetcher, *args)) for fetcher, args, _got in calls]

    for fresh, got in map_forked(fetch_all, [0, 1, 2, 3], 4):
        assert fresh
        assert got == [repr(expected) for _fetcher, _args, expected in calls]
