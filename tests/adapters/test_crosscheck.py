"""Independent readers and end-to-end use: Rerun's MCAP reader agrees on /tf; replay from a log
gives the world points the scene put there; the info and tf commands print what they must."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain.adapters import open_log, write_log
from framechain.cli.main import main
from framechain.config.chain import ChainConfig
from framechain.replay import REPLAYED, replay
from framechain.timeline import CameraTable, DepthFrameTable, ObservationTable, Timeline, TransformTable
from tests.helpers.adapter_scene import CHAIN, OPTICAL_Q, T0, K, body_pose


def test_rerun_mcap_reader_agrees_on_tf(written: dict[str, Path]) -> None:
    import pandas as pd
    import rerun.chunk as rc

    path = written["mcap-ros2"]
    rows = []
    for chunk in rc.McapReader(str(path), include_topic_regex=["/tf.*"]).stream():
        batch = chunk.to_record_batch()
        if "Transform3D:translation" not in batch.schema.names:
            continue
        for r in batch.to_pylist():
            rows.append((int(pd.Timestamp(r["message_log_time"]).value), r["Transform3D:parent_frame"][0],
                         r["Transform3D:child_frame"][0], r["Transform3D:translation"][0],
                         r["Transform3D:quaternion"][0]))
    tf = open_log(path).timeline.transforms
    assert len(rows) == len(tf) == 52
    ours = sorted(zip(tf.log_time_ns.tolist(), tf.parent.tolist(), tf.child.tolist(), range(len(tf)), strict=True))
    theirs = sorted(rows, key=lambda r: (r[0], r[1], r[2]))
    for (log_ns, parent, child, i), (r_log, r_parent, r_child, r_t, r_q) in zip(ours, theirs, strict=True):
        assert (log_ns, parent, child) == (r_log, r_parent, r_child)
        np.testing.assert_allclose(r_t, tf.translation[i], rtol=1e-6, atol=1e-7)  # Rerun stores float32
        assert abs(float(np.dot(r_q, tf.quat_xyzw[i]))) == pytest.approx(1.0, abs=1e-6)


def test_replay_from_a_log_recovers_the_world_points(tmp_path: Path) -> None:
    """Pixel + depth image + CameraInfo + TF from a .bag give the scene's world points (within mm)."""
    rng = np.random.default_rng(7)
    n_tf, w, h = 60, 640, 480
    stamps = T0 + np.arange(n_tf, dtype=np.int64) * 50_000_000
    xyz, q = body_pose((stamps - T0) * 1e-9)
    transforms = TransformTable.concat([
        TransformTable.from_rows("map", "base_link", stamps, xyz, q, log_time_ns=stamps + 2_000_000, source="/tf"),
        TransformTable.from_rows("base_link", "camera_optical_frame", [T0], [0.3, 0.0, 0.8], OPTICAL_Q,
                                 is_static=True, source="/tf_static"),
    ])
    obs_t = stamps[10:50:4]
    n = obs_t.size
    u, v = rng.uniform(100, 540, n), rng.uniform(80, 400, n)
    z = rng.uniform(1.0, 3.0, n)
    # Truth by independent maths: pinhole, then scipy rotations, pose at the observation stamp.
    p_cam = np.column_stack([(np.rint(u) - K["cx"]) * z / K["fx"], (np.rint(v) - K["cy"]) * z / K["fy"], z])
    p_body = Rotation.from_quat(OPTICAL_Q).apply(p_cam) + np.array([0.3, 0.0, 0.8])
    bx, bq = body_pose((obs_t - T0) * 1e-9)
    truth = Rotation.from_quat(bq).apply(p_body) + bx
    images = np.zeros((n, h, w), dtype=np.float32)
    for k in range(n):  # a flat patch of the true depth (millimetres) around each pixel
        r, c = int(np.rint(v[k])), int(np.rint(u[k]))
        images[k, r - 3 : r + 4, c - 3 : c + 4] = np.round(z[k], 3)
    depth = DepthFrameTable.from_arrays("camera_optical_frame", obs_t, images, source="/camera/depth/image_rect_raw")
    obs = ObservationTable(obs_id=np.arange(n), stamp_ns=obs_t, log_time_ns=obs_t + 30_000_000,
                           camera_frame=np.full(n, "camera_optical_frame"), u=np.rint(u), v=np.rint(v),
                           depth_m=np.full(n, np.nan), label=np.full(n, "cup"), score=np.ones(n),
                           source=np.full(n, "/detections"))
    cams = CameraTable.from_intrinsics("camera_optical_frame", **K, width=w, height=h, stamp_ns=T0,
                                       source="/camera/color/camera_info")
    scene = Timeline(transforms=transforms, cameras=cams, observations=obs, depth_frames=depth)
    path = write_log(scene, tmp_path / "e2e.bag", container="rosbag1", chain=CHAIN)
    loaded = open_log(path, CHAIN)
    result = replay(loaded.timeline, CHAIN.frames)
    assert (result.status == REPLAYED).all()
    np.testing.assert_allclose(result.p_world, truth, atol=2e-3)  # mm quantisation of 16UC1 depth


def test_info_terminal_output_and_chain_yaml(written: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(written["rosbag2-mcap"])]) == 0
    out = capsys.readouterr().out
    for text in ("rosbag2 (mcap)", "Frame tree", "map", "odom", "base_link", "camera_optical_frame", "static",
                 "/camera/color/camera_info", "Suggested chain"):
        assert text in out
    assert main(["info", str(written["rosbag2-mcap"]), "--chain"]) == 0
    chain = ChainConfig.from_dict(__import__("yaml").safe_load(capsys.readouterr().out))
    assert chain.frames.camera == "camera_optical_frame"
    assert chain.frames.world == "map"
    assert chain.topics.detections == "/detections"
    assert chain.topics.depth == "/camera/depth/image_rect_raw"
    assert main(["info", str(written["rosbag2-mcap"]), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    odom = next(e for e in info["edges"] if e["child"] == "base_link")
    assert odom["count"] == 40
    assert odom["rate_hz"] == pytest.approx(20.0)
    # Scene delays: log time = stamp + 1..5 ms.
    assert 1e-3 <= odom["delay_mean_s"] <= odom["delay_p95_s"] <= odom["delay_max_s"] < 5e-3


def test_tf_command_at_json_csv_and_series(written: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    log = str(written["mcap-ros1"])
    # Halfway between the samples at 0.10 s and 0.15 s: tf2 interpolation, checked by hand.
    assert main(["tf", log, "odom", "camera_optical_frame", "--at", "0.125", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    t = 0.125
    bx = np.array([1.0 + 0.5 * t, 0.5 + 0.05 * (np.sin(0.10) + np.sin(0.15)), 0.0])
    yaw = 0.2 * t
    expected = Rotation.from_euler("z", yaw).apply([0.3, 0.0, 0.8]) + bx
    np.testing.assert_allclose(r["translation"], expected, atol=1e-12)
    q_exp = (Rotation.from_euler("z", yaw) * Rotation.from_quat(OPTICAL_Q)).as_quat()
    assert abs(float(np.dot(r["quat_xyzw"], q_exp))) == pytest.approx(1.0, abs=1e-12)
    assert r["path"] == ["camera_optical_frame", "camera_link", "base_link", "odom"]
    assert r["stamp_ns"] == T0 + 125_000_000
    dyn = next(h for h in r["hops"] if not h["static"])
    assert dyn["stamps_ns"] == [T0 + 100_000_000, T0 + 150_000_000]
    assert dyn["weight"] == pytest.approx(0.5)
    np.testing.assert_allclose(r["rpy_deg"], Rotation.from_quat(r["quat_xyzw"]).as_euler("xyz", degrees=True))
    assert main(["tf", log, "odom", "camera_optical_frame", "--at", "0.125", "--csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert float(rows[0]["x"]) == pytest.approx(expected[0], abs=1e-12)
    assert main(["tf", log, "map", "camera_link", "--series"]) == 0
    series = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    # map->odom sampled every 0.2 s over 0..1.8 s, odom->base_link every 0.05 s: the union in the common span.
    assert len(series) == 37
    assert int(series[0]["stamp_ns"]) == T0
    assert int(series[-1]["stamp_ns"]) == T0 + 1_800_000_000
    assert main(["tf", log, "base_link", "camera_optical_frame"]) == 0
    text = capsys.readouterr().out
    assert "Translation: [0.300000, 0.000000, 0.800000]" in text
    assert "Matrix" in text
