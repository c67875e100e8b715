"""Mounts and URDF fixed joints from the chain file as static edges; pose topics (PoseStamped,
PoseWithCovarianceStamped, TransformStamped, Odometry) as dynamic edges. Bags written with rosbags'
writers; expected values from scipy, yourdfpy and hand-worked interpolation."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from framechain.adapters import open_log
from framechain.cli.main import main
from framechain.config.chain import ChainConfig
from framechain.config.errors import ChainConfigError
from framechain.errors import FramechainError
from framechain.replay import TransformBuffer

T0 = 1_700_000_000 * 10**9
NS = 10**9


class Bag:
    """A ROS 2 (sqlite) or ROS 1 bag written with rosbags' writers, one message list per topic."""

    def __init__(self, *, ros1: bool = False) -> None:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        self.ros1 = ros1
        self.ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        if ros1:  # ROS1_NOETIC has no tf2_msgs
            self.ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                "tf2_msgs/msg/TFMessage"))
        self.T = self.ts.types
        self.topics: dict[str, tuple[str, list[tuple[int, Any]]]] = {}

    def add(self, topic: str, msgtype: str, t_ns: int, msg: Any) -> None:
        self.topics.setdefault(topic, (msgtype, []))[1].append((t_ns, msg))

    def write(self, path: Path) -> Path:
        from rosbags.rosbag1 import Writer as Writer1
        from rosbags.rosbag2 import Writer as Writer2

        writer: Any = Writer1(path) if self.ros1 else Writer2(path, version=9)
        with writer as w:
            for topic, (msgtype, msgs) in self.topics.items():
                c = w.add_connection(topic, msgtype, typestore=self.ts)
                for t, m in msgs:
                    data = self.ts.serialize_ros1(m, msgtype) if self.ros1 else self.ts.serialize_cdr(m, msgtype)
                    w.write(c, t, bytes(data))
        return path

    def header(self, t_ns: int, frame: str) -> Any:
        T = self.T
        stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // NS, nanosec=t_ns % NS)
        if self.ros1:
            return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def pose(self, xyz: Any, quat: Any) -> Any:
        T = self.T
        return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=xyz[0], y=xyz[1], z=xyz[2]),
                                           orientation=T["geometry_msgs/msg/Quaternion"](
                                               x=quat[0], y=quat[1], z=quat[2], w=quat[3]))

    def transform(self, t_ns: int, parent: str, child: str, xyz: Any, quat: Any) -> Any:
        T = self.T
        return T["geometry_msgs/msg/TransformStamped"](
            header=self.header(t_ns, parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=xyz[0], y=xyz[1], z=xyz[2]),
                rotation=T["geometry_msgs/msg/Quaternion"](x=quat[0], y=quat[1], z=quat[2], w=quat[3])))

    def tf(self, topic: str, t_ns: int, parent: str, child: str, xyz: Any, quat: Any) -> None:
        msg = self.T["tf2_msgs/msg/TFMessage"](transforms=[self.transform(t_ns, parent, child, xyz, quat)])
        self.add(topic, "tf2_msgs/msg/TFMessage", t_ns, msg)

    def pose_msg(self, msgtype: str, t_ns: int, parent: str, xyz: Any, quat: Any, child: str = "") -> Any:
        T = self.T
        if msgtype == "geometry_msgs/msg/PoseStamped":
            return T[msgtype](header=self.header(t_ns, parent), pose=self.pose(xyz, quat))
        if msgtype == "geometry_msgs/msg/PoseWithCovarianceStamped":
            return T[msgtype](header=self.header(t_ns, parent), pose=T["geometry_msgs/msg/PoseWithCovariance"](
                pose=self.pose(xyz, quat), covariance=np.zeros(36)))
        if msgtype == "geometry_msgs/msg/TransformStamped":
            return self.transform(t_ns, parent, child, xyz, quat)
        twist = T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                                               angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
            covariance=np.zeros(36))
        return T["nav_msgs/msg/Odometry"](header=self.header(t_ns, parent), child_frame_id=child,
                                          pose=T["geometry_msgs/msg/PoseWithCovariance"](
                                              pose=self.pose(xyz, quat), covariance=np.zeros(36)), twist=twist)


def _chain(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "chain.yaml"
    path.write_text(text)
    return path


def _base_bag(tmp_path: Path) -> Path:
    """odom -> base_link moving on /tf, base_link -> camera_link on /tf_static (a wrong mount)."""
    bag = Bag()
    for k in range(5):
        t = T0 + k * NS // 10
        bag.tf("/tf", t, "odom", "base_link", [0.1 * k, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    bag.tf("/tf_static", T0, "base_link", "camera_link", [0.2, 0.0, 0.5], [0.0, 0.0, 0.0, 1.0])
    return bag.write(tmp_path / "base")


@pytest.mark.parametrize(("key", "value", "expected"), [
    ("quat_xyzw", [0.1, -0.2, 0.3, 0.9273618495495703], Rotation.from_quat([0.1, -0.2, 0.3, 0.9273618495495703])),
    ("rpy", [0.3, -0.2, 1.1], Rotation.from_euler("xyz", [0.3, -0.2, 1.1])),
    ("rotvec", [0.0135696, -0.0062165, 3.1391944], Rotation.from_rotvec([0.0135696, -0.0062165, 3.1391944])),
])
def test_mount_rotations_match_scipy_and_tf_gives_the_mount_back(
    key: str, value: list[float], expected: Rotation, tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    log = _base_bag(tmp_path)
    mount = f"{{parent: camera_link, child: cam_optical, xyz: [0.01, 0.02, 0.03], {key}: {value}}}"
    chain = _chain(tmp_path, f"frames: {{camera: cam_optical, body: base_link, world: odom}}\nmounts:\n  - {mount}\n")
    config = ChainConfig.from_yaml(chain)
    q = np.asarray(config.mounts[0].quat_xyzw)
    assert abs(float(q @ expected.as_quat())) == pytest.approx(1.0, abs=1e-12)  # same rotation, up to sign
    assert main(["tf", str(log), "camera_link", "cam_optical", "--chain", str(chain), "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(record["translation"], [0.01, 0.02, 0.03], atol=1e-15)
    assert abs(float(np.dot(record["quat_xyzw"], expected.as_quat()))) == pytest.approx(1.0, abs=1e-12)
    assert record["hops"][0]["static"]
    assert record["hops"][0]["source"] == "chain.yaml mounts[0]"


def test_mount_wins_over_the_logs_edge_with_a_note(tmp_path: Path) -> None:
    log = _base_bag(tmp_path)
    chain = _chain(tmp_path, "frames: {camera: camera_link, body: base_link, world: odom}\n"
                   "mounts:\n  - {parent: base_link, child: camera_link, xyz: [0.3, 0.0, 0.8], rpy: [0, 0.1, 0]}\n")
    loaded = open_log(log, ChainConfig.from_yaml(chain))
    tf = loaded.timeline.transforms
    cam = tf.take(tf.child == "camera_link")
    assert len(cam) == 1
    assert cam.source.tolist() == ["chain.yaml mounts[0]"]
    assert bool(cam.is_static[0])
    np.testing.assert_allclose(cam.translation[0], [0.3, 0.0, 0.8])
    note = next(n for n in loaded.info.notes if n.startswith("chain.yaml mounts[0]"))
    assert "xyz [0.3, 0, 0.8]" in note  # the mount's value
    assert "xyz [0.2, 0, 0.5]" in note  # the log's value
    assert "/tf_static" in note
    # |[0.3, 0, 0.8] - [0.2, 0, 0.5]| = sqrt(0.01 + 0.09) = 316.2 mm; 0.1 rad = 5.73 deg
    assert "316.2 mm and 5.73 deg" in note


def test_mount_under_a_moving_frame_must_be_given_the_other_way_round(
    tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    log = _base_bag(tmp_path)  # odom -> base_link moves on /tf
    chain = _chain(tmp_path, "mounts:\n  - {parent: rig, child: base_link, xyz: [0, 0, 0], rotvec: [0, 0, 3.14]}\n")
    assert main(["tf", str(log), "odom", "base_link", "--chain", str(chain)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "chain.yaml mounts[0]: frame 'base_link' already has the moving parent 'odom' in the log (/tf)" in err
    assert "(parent: base_link, child: rig, the inverse transform)" in err


def test_mount_errors_are_one_line(tmp_path: Path) -> None:
    with pytest.raises(ChainConfigError, match=r"mounts\[0\]: two rotations \(quat_xyzw and rpy\)") as err:
        ChainConfig.from_dict({"mounts": [{"parent": "a", "child": "b", "xyz": [0, 0, 0],
                                           "quat_xyzw": [0, 0, 0, 1], "rpy": [0, 0, 0]}]})
    assert "\n" not in str(err.value)
    with pytest.raises(ChainConfigError, match=r"mounts\[1\]: no rotation"):
        ChainConfig.from_dict({"mounts": [{"parent": "a", "child": "b", "rpy": [0, 0, 0]},
                                          {"parent": "b", "child": "c", "xyz": [1, 0, 0]}]})
    with pytest.raises(ChainConfigError, match=r"mounts\[0\]: quat_xyzw .* has norm 2, not 1"):
        ChainConfig.from_dict({"mounts": [{"parent": "a", "child": "b", "quat_xyzw": [0, 0, 0, 2]}]})
    with pytest.raises(ChainConfigError, match=r"mounts\[0\]: unknown keys \['rpy_deg'\]"):
        ChainConfig.from_dict({"mounts": [{"parent": "a", "child": "b", "rpy_deg": [0, 0, 0]}]})
    log = _base_bag(tmp_path)
    chain = _chain(tmp_path, "mounts:\n  - {parent: a, child: b, xyz: [0, 0, 0], rotvec: [0, 0, 0], rpy: [0, 0, 0]}\n")
    assert main(["tf", str(log), "a", "b", "--chain", str(chain)]) == 1


URDF = """<?xml version="1.0"?>
<robot name="rig">
  <link name="base_link"/><link name="mast"/><link name="camera_link"/><link name="camera_optical"/>
  <link name="wheel"/>
  <joint name="mast_joint" type="fixed">
    <parent link="base_link"/><child link="mast"/>
    <origin xyz="0.1 -0.05 0.6" rpy="0.05 -0.3 1.2"/>
  </joint>
  <joint name="camera_joint" type="fixed">
    <parent link="mast"/><child link="camera_link"/>
    <origin xyz="0.02 0 0.1" rpy="0 0.35 0"/>
  </joint>
  <joint name="optical_joint" type="fixed">
    <parent link="camera_link"/><child link="camera_optical"/>
    <origin xyz="0 0.015 0" rpy="-1.5707963267948966 0 -1.5707963267948966"/>
  </joint>
  <joint name="wheel_joint" type="continuous">
    <parent link="base_link"/><child link="wheel"/><axis xyz="0 1 0"/>
    <origin xyz="0 0.2 0.1"/>
  </joint>
  <transmission name="t"><joint name="wheel_joint"/></transmission>
</robot>
"""


def test_urdf_fixed_joints_match_yourdfpy(tmp_path: Path) -> None:
    import yourdfpy

    (tmp_path / "rig.urdf").write_text(URDF)
    bag = Bag()
    for k in range(3):
        bag.tf("/tf", T0 + k * NS, "odom", "base_link", [0.1 * k, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    log = bag.write(tmp_path / "log")
    chain = _chain(tmp_path, "frames: {camera: camera_optical, body: base_link, world: odom}\nurdf: rig.urdf\n")
    loaded = open_log(log, ChainConfig.from_yaml(chain))
    tf = loaded.timeline.transforms
    assert sorted(tf.child[tf.is_static].tolist()) == ["camera_link", "camera_optical", "mast"]  # not the wheel
    assert set(tf.source[tf.is_static].tolist()) == {"rig.urdf"}
    buffer = TransformBuffer(tf)
    robot = yourdfpy.URDF.load(str(tmp_path / "rig.urdf"), load_meshes=False)
    for frame in ("mast", "camera_link", "camera_optical"):
        expected = robot.get_transform(frame_to=frame, frame_from="base_link")  # T_base_link_frame
        got = buffer.lookup("base_link", frame, np.array([T0 + NS])).matrix()[0]
        np.testing.assert_allclose(got, expected, atol=1e-12)


def test_robot_description_in_the_log_fills_only_missing_edges(tmp_path: Path) -> None:
    bag = Bag()
    bag.tf("/tf", T0, "odom", "base_link", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    # The log publishes base_link -> mast itself; the description must not replace it.
    bag.tf("/tf_static", T0, "base_link", "mast", [9.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    bag.add("/robot_description", "std_msgs/msg/String", T0, bag.T["std_msgs/msg/String"](data=URDF))
    loaded = open_log(bag.write(tmp_path / "log"))
    tf = loaded.timeline.transforms
    mast = tf.take(tf.child == "mast")
    assert mast.source.tolist() == ["/tf_static"]
    assert mast.translation[0, 0] == 9.0
    assert set(tf.source[np.isin(tf.child, ["camera_link", "camera_optical"])].tolist()) == {"/robot_description"}
    assert any("/robot_description: 2 fixed joints of the robot description added" in n for n in loaded.info.notes)


def _slerp_lerp(t0: int, t1: int, x0: Any, x1: Any, q0: Any, q1: Any, t: int) -> tuple[np.ndarray, np.ndarray]:
    """Hand-computed tf2 interpolation: translation linear, rotation slerp, ratio (t - t0) / (t1 - t0)."""
    r = (t - t0) / (t1 - t0)
    xyz = (1 - r) * np.asarray(x0) + r * np.asarray(x1)
    quat = Slerp([0.0, 1.0], Rotation.from_quat([q0, q1]))([r]).as_quat()[0]
    return xyz, quat


@pytest.mark.parametrize("msgtype", [
    "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped",
    "geometry_msgs/msg/TransformStamped", "nav_msgs/msg/Odometry",
])
def test_pose_topics_are_dynamic_edges_interpolated_like_tf2(msgtype: str, tmp_path: Path) -> None:
    x0, x1 = [1.0, 2.0, 0.0], [2.0, 1.0, 0.5]
    q0 = Rotation.from_euler("xyz", [0.1, 0.0, 0.2]).as_quat()
    q1 = Rotation.from_euler("xyz", [0.0, -0.2, 1.4]).as_quat()
    t0, t1 = T0, T0 + NS // 5
    bag = Bag()
    for t, x, q in ((t0, x0, q0), (t1, x1, q1)):
        bag.add("/vio/pose", msgtype, t, bag.pose_msg(msgtype, t, "world", x, q, child="imu"))
    log = bag.write(tmp_path / "log")
    has_child = msgtype in ("geometry_msgs/msg/TransformStamped", "nav_msgs/msg/Odometry")
    chain = _chain(tmp_path, "frames: {camera: cam, body: rig, world: world}\ntopics:\n  odometry: /vio/pose\n")
    loaded = open_log(log, ChainConfig.from_yaml(chain))
    child = "imu" if has_child else "rig"  # no child in the message: the chain's body frame, with a note
    assert loaded.decoded_topics["/vio/pose"] in ("pose", "odometry")
    if not has_child:
        assert any("no child frame in the message; 'rig' (the chain's frames.body)" in n for n in loaded.info.notes)
    half = (t0 + t1) // 2 + 12_345_678  # not exactly halfway: the ratio matters
    result = TransformBuffer(loaded.timeline.transforms).lookup("world", child, np.array([half]))
    result.raise_for_status()
    xyz, quat = _slerp_lerp(t0, t1, x0, x1, q0, q1, half)
    np.testing.assert_allclose(result.translation[0], xyz, atol=1e-12)
    assert abs(float(result.quat_xyzw[0] @ quat)) == pytest.approx(1.0, abs=1e-12)


def test_pose_topics_as_a_list_with_a_named_child(tmp_path: Path) -> None:
    bag = Bag()
    for k in range(2):
        t = T0 + k * NS
        bag.add("/mocap/rig", "geometry_msgs/msg/PoseStamped", t,
                bag.pose_msg("geometry_msgs/msg/PoseStamped", t, "mocap", [k, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]))
        bag.add("/odom", "nav_msgs/msg/Odometry", t,
                bag.pose_msg("nav_msgs/msg/Odometry", t, "odom", [0.0, k, 0.0], [0.0, 0.0, 0.0, 1.0],
                             child="base_link"))
    log = bag.write(tmp_path / "log")
    chain = _chain(tmp_path, "frames: {camera: cam, body: base_link, world: odom}\n"
                   "topics:\n  odometry: [/odom, {topic: /mocap/rig, child: rig_marker}]\n")
    config = ChainConfig.from_yaml(chain)
    assert [(p.topic, p.child) for p in config.pose_topics()] == [("/odom", None), ("/mocap/rig", "rig_marker")]
    tf = open_log(log, config).timeline.transforms
    assert set(zip(tf.parent.tolist(), tf.child.tolist(), strict=True)) == {("odom", "base_link"),
                                                                              ("mocap", "rig_marker")}


def test_pose_stamped_named_as_evidence_stays_a_point(tmp_path: Path) -> None:
    bag = Bag()
    bag.tf("/tf", T0, "map", "base_link", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    bag.add("/grasp_target", "geometry_msgs/msg/PoseStamped", T0,
            bag.pose_msg("geometry_msgs/msg/PoseStamped", T0, "map", [1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0]))
    log = bag.write(tmp_path / "log")
    chain = _chain(tmp_path, "frames: {camera: cam, body: base_link, world: map}\nevidence: {target: /grasp_target}\n")
    loaded = open_log(log, ChainConfig.from_yaml(chain))
    assert loaded.decoded_topics["/grasp_target"] == "point"
    np.testing.assert_allclose(loaded.timeline.points.xyz, [[1.0, 2.0, 3.0]])
    assert "/grasp_target" not in set(loaded.timeline.transforms.source.tolist())


def test_ros1_odometry_with_leading_slashes_and_no_child(tmp_path: Path) -> None:
    """Like the old Husky bags: frame_id "/odom", child_frame_id ""."""
    bag = Bag(ros1=True)
    for k in range(3):
        t = T0 + k * NS
        bag.add("/wheel_odometry", "nav_msgs/msg/Odometry", t,
                bag.pose_msg("nav_msgs/msg/Odometry", t, "/odom", [k, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0], child=""))
    log = bag.write(tmp_path / "husky.bag")
    chain = _chain(tmp_path, "frames: {camera: cam, body: base_footprint, world: odom}\n"
                   "topics: {odometry: /wheel_odometry}\n")
    loaded = open_log(log, ChainConfig.from_yaml(chain))
    tf = loaded.timeline.transforms
    assert set(zip(tf.parent.tolist(), tf.child.tolist(), strict=True)) == {("odom", "base_footprint")}
    assert any(n.startswith("topic /wheel_odometry: no child frame in the message; 'base_footprint'")
               and "(3 messages)" in n for n in loaded.info.notes)


def test_info_and_tf_show_mounts_as_static_edges(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("COLUMNS", "200")  # rich wraps table cells at 80 columns
    log = _base_bag(tmp_path)
    chain = _chain(tmp_path, "frames: {camera: cam_optical, body: base_link, world: odom}\n"
                   "mounts:\n  - {parent: camera_link, child: cam_optical, xyz: [0, 0.015, 0], "
                   "quat_xyzw: [-0.5, 0.5, -0.5, 0.5]}\n")
    assert main(["info", str(log), "--chain-file", str(chain), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    by = {(e["parent"], e["child"]): e for e in info["edges"]}
    assert by[("camera_link", "cam_optical")]["static"]
    assert by[("camera_link", "cam_optical")]["sources"] == ["chain.yaml mounts[0]"]
    assert by[("base_link", "camera_link")]["sources"] == ["/tf_static"]
    assert main(["info", str(log), "--chain-file", str(chain)]) == 0
    text = capsys.readouterr().out
    assert "cam_optical  static (chain.yaml mounts[0])" in text
    # odom -> base_link at 0.15 s: x = 0.15 (halfway between 0.1 and 0.2); + camera_link [0.2, 0, 0.5]; + the
    # mount [0, 0.015, 0] (no rotation above it): [0.35, 0.015, 0.5].
    assert main(["tf", str(log), "odom", "cam_optical", "--chain", str(chain), "--at", "0.15"]) == 0
    text = capsys.readouterr().out
    assert "static (chain.yaml mounts[0])" in text
    assert "- Translation: [0.350000, 0.015000, 0.500000]" in text


def test_mount_wins_over_the_chains_urdf_and_two_mounts_of_one_frame_are_an_error(tmp_path: Path) -> None:
    (tmp_path / "rig.urdf").write_text(URDF)
    bag = Bag()
    bag.tf("/tf", T0, "odom", "base_link", [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0])
    log = bag.write(tmp_path / "log")
    chain = _chain(tmp_path, "urdf: rig.urdf\n"
                   "mounts:\n  - {parent: mast, child: camera_link, xyz: [0.5, 0, 0], quat_xyzw: [0, 0, 0, 1]}\n")
    loaded = open_log(log, ChainConfig.from_yaml(chain))
    tf = loaded.timeline.transforms
    cam = tf.take(tf.child == "camera_link")
    assert cam.source.tolist() == ["chain.yaml mounts[0]"]
    np.testing.assert_allclose(cam.translation[0], [0.5, 0.0, 0.0])
    assert "rig.urdf: fixed joint mast -> camera_link not used; chain.yaml mounts[0] gives that frame" in (
        loaded.info.notes)
    twice = _chain(tmp_path, "mounts:\n  - {parent: a, child: b, rpy: [0, 0, 0]}\n"
                   "  - {parent: c, child: b, rpy: [0, 0, 0]}\n")
    with pytest.raises(FramechainError, match=r"chain.yaml mounts\[1\]: frame 'b' is already the child of "
                       r"chain.yaml mounts\[0\]"):
        open_log(log, ChainConfig.from_yaml(twice))
