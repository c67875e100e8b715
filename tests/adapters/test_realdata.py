"""Real logs in ../shared/realdata: every ROS log reads in `framechain info` with the right tree,
topics and clock notes; librealsense mapping; Franka ROS 1 = ROS 2 = URDF forward kinematics."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain.adapters import open_log
from framechain.cli.main import main
from framechain.replay import LATEST, TransformBuffer
from framechain.suggest import frame_tree
from tests.helpers.realdata import (
    ARUCO_IMAGES_BAG,
    ARUCO_MARKER_BAG,
    FRANKA_BAG,
    FRANKA_ROS2,
    HUSKY_BAG,
    HUSKY_OLD_FRAMES_BAG,
    NAV2_MCAP,
    PANDA_URDF,
    REALSENSE_BAG,
    TF_EXAMPLE_BAG,
    TF_EXAMPLE_ROS2,
    TURTLESIM_BAG,
)

#: log -> (edges "parent>child" with static flag, sample counts of dynamic edges)
TREES: dict[str, dict[str, tuple[bool, int]]] = {
    TF_EXAMPLE_BAG: {"odom>base_footprint": (False, 517), "base_footprint>base_link": (True, 1)},
    TF_EXAMPLE_ROS2: {"odom>base_footprint": (False, 517), "base_footprint>base_link": (True, 1)},
    TURTLESIM_BAG: {"world>turtle1": (False, 1344), "world>turtle2": (False, 1344), "turtle1>carrot": (True, 1)},
    HUSKY_BAG: {"odom>base_link": (False, 3952)},
    ARUCO_IMAGES_BAG: {},
    ARUCO_MARKER_BAG: {},
}


def _info_json(path: Path, capsys: pytest.CaptureFixture[str]) -> dict:  # type: ignore[type-arg]
    assert main(["info", str(path), "--json"]) == 0
    out: dict = json.loads(capsys.readouterr().out)  # type: ignore[type-arg]
    return out


@pytest.mark.parametrize("name", sorted(TREES))
def test_info_reads_real_logs(name: str, realdata: Path, capsys: pytest.CaptureFixture[str]) -> None:
    info = _info_json(realdata / name, capsys)
    edges = {f"{e['parent']}>{e['child']}": (e["static"], e["count"]) for e in info["edges"]}
    assert edges == TREES[name]


#: Every ROS log in realdata, including those checked more closely below.
ALL_ROS_LOGS = [*sorted(TREES), NAV2_MCAP, HUSKY_OLD_FRAMES_BAG,
                FRANKA_BAG, FRANKA_ROS2, REALSENSE_BAG]


@pytest.mark.parametrize("name", ALL_ROS_LOGS)
def test_info_reads_every_ros_log(name: str, realdata: Path, capsys: pytest.CaptureFixture[str]) -> None:
    info = _info_json(realdata / name, capsys)
    # Every topic is listed with its type, and the counts are those of the file, not of what was kept.
    assert info["topics"]
    assert all(t["msgtype"] and t["count"] > 0 for t in info["topics"])


def test_tf_static_path_is_timeless(realdata: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = str(realdata / TF_EXAMPLE_BAG)
    assert main(["tf", log, "base_footprint", "base_link", "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["timeless"] is True
    assert record["stamp_ns"] is None
    assert record["t_rel_s"] is None
    assert main(["tf", log, "odom", "base_link", "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert record["timeless"] is False
    assert record["stamp_ns"] > 1_700_000_000 * 10**9
    assert record["t_rel_s"] >= 0


def test_turtlebot_sim_time_is_pointed_out(realdata: Path, capsys: pytest.CaptureFixture[str]) -> None:
    info = _info_json(realdata / NAV2_MCAP, capsys)
    assert len(info["edges"]) == 33
    by = {(e["parent"], e["child"]): e for e in info["edges"]}
    assert by[("map", "odom")]["clocks_differ"]
    assert not by[("map", "odom")]["static"]
    assert by[("oakd_rgb_camera_frame", "oakd_rgb_camera_optical_frame")]["static"]
    note = next(n for n in info["notes"] if n.startswith("topic /tf:"))
    assert "simulation time" in note
    assert "wall clock" in note
    assert info["suggested_chain"]["frames"] == {"camera": "oakd_rgb_camera_optical_frame", "body": "base_link",
                                                 "world": "map"}
    # /odom duplicates the /tf edge odom -> base_link: one source, not two parents.
    assert by[("odom", "base_link")]["sources"] == ["/tf"]


def test_husky_old_frames_and_empty_child(realdata: Path) -> None:
    loaded = open_log(realdata / HUSKY_OLD_FRAMES_BAG)
    edges = {(e.parent, e.child) for e in frame_tree(loaded.timeline.transforms)}
    assert all(not p.startswith("/") and not c.startswith("/") for p, c in edges)
    assert any("no child frame in the message; 'base_link'" in n for n in loaded.info.notes)


def test_fiducials_cameras_and_clock_gap(realdata: Path, capsys: pytest.CaptureFixture[str]) -> None:
    info = _info_json(realdata / ARUCO_MARKER_BAG, capsys)
    cam = info["cameras"][0]
    assert (cam["width"], cam["height"], cam["distortion_model"]) == (1280, 720, "plumb_bob")
    assert any("13293" in n and "behind log time" in n for n in info["notes"])
    imgs = _info_json(realdata / ARUCO_IMAGES_BAG, capsys)
    assert (imgs["cameras"][0]["width"], imgs["cameras"][0]["height"]) == (1280, 960)


def test_realsense_depth_pixel_into_colour_camera(realdata: Path) -> None:
    loaded = open_log(realdata / REALSENSE_BAG)
    tl = loaded.timeline
    depth_frame, color_frame = "device_0/sensor_0/Depth_0", "device_0/sensor_1/Color_0"
    assert sorted(tl.cameras.frame.tolist()) == [depth_frame, color_frame]
    assert len(tl.depth_frames) == 6
    assert set(tl.depth_frames.frame.tolist()) == {depth_frame}
    image = tl.depth_frames.load(0)
    assert image.shape == (480, 640)
    valid = image[(image > 0) & np.isfinite(image)]
    assert 0.1 < float(np.median(valid)) < 10.0  # Depth_Units 0.001: millimetres to metres
    cams = {str(f): tl.cameras.K[i] for i, f in enumerate(tl.cameras.frame)}
    # Numbers read from the bag by hand (rosbags, message by message).
    assert cams[depth_frame][0, 0] == pytest.approx(388.16558838)
    assert cams[color_frame][0, 0] == pytest.approx(604.21337891)
    t_cd = np.array([0.01516044046729803, -6.988984387135133e-05, -4.144782724324614e-05])
    q_cd = np.array([0.0003198388440068811, -0.0011914061615243554, 0.006333452649414539, -0.9999791383743286])
    lookup = TransformBuffer(tl.transforms).lookup(color_frame, depth_frame, LATEST)
    lookup.raise_for_status()
    v, u = 240, 320
    rows, cols = np.nonzero(image > 0)
    k = int(np.argmin((rows - v) ** 2 + (cols - u) ** 2))
    v, u = int(rows[k]), int(cols[k])
    z = float(image[v, u])
    p_depth = np.linalg.solve(cams[depth_frame], np.array([u, v, 1.0])) * z
    p_color = lookup.apply(p_depth)[0]
    expected = Rotation.from_quat(q_cd).apply(p_depth) + t_cd
    np.testing.assert_allclose(p_color, expected, atol=1e-12)
    uv = cams[color_frame] @ (p_color / p_color[2])
    naive = cams[color_frame] @ (p_depth / p_depth[2])
    # The 15 mm baseline shifts the pixel by about fx * 0.015 / Z along u (the 0.14 deg pitch adds ~1.5 px).
    assert uv[0] - naive[0] == pytest.approx(604.2 * 0.01516 / z, abs=2.5)


def test_franka_ros1_ros2_and_urdf_forward_kinematics(realdata: Path) -> None:
    import yourdfpy

    r1 = open_log(realdata / FRANKA_BAG).timeline
    r2 = open_log(realdata / FRANKA_ROS2).timeline
    js = r1.joint_states.take(r1.joint_states.source == "/joint_states")
    robot = yourdfpy.URDF.load(str(realdata / PANDA_URDF), build_scene_graph=True, load_meshes=False)
    names = list(robot.actuated_joint_names)
    stamps, q = js.wide(names)
    assert stamps.size == 110
    b1, b2 = TransformBuffer(r1.transforms), TransformBuffer(r2.transforms)
    for link in ("panda_link4", "panda_hand", "panda_hand_tcp"):
        l1 = b1.lookup("panda_link0", link, stamps)
        l2 = b2.lookup("panda_link0", link, stamps)
        assert l1.ok.all()
        assert l2.ok.all()
        np.testing.assert_allclose(l1.matrix(), l2.matrix(), atol=1e-12)
        for i in range(stamps.size):
            robot.update_cfg(dict(zip(names, q[i], strict=True)))
            fk = robot.get_transform(frame_to=link, frame_from="panda_link0")
            np.testing.assert_allclose(l1.matrix()[i], fk, atol=1e-9)


def test_legacy_tf_on_two_connections(realdata: Path) -> None:
    loaded = open_log(realdata / TURTLESIM_BAG)
    assert loaded.decoded_topics["/tf"] == "tf"
    tf = loaded.timeline.transforms
    assert int((tf.child == "turtle1").sum()) == 1344
    assert int((tf.child == "turtle2").sum()) == 1344
