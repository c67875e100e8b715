"""The shared stairs log (TagSLAM's test 21: AprilTags on a house's static tags, Basalt VIO odometry) as the tests
read it: the chain the files beside the bag describe, its attribution made once per process, and copies of the bag
with the odometry restamped (rosbags' own writer).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.analysis.verdict.findings import Attribution
from framechain.config.chain import ChainConfig
from tests.helpers.realdata import STAIRS, STAIRS_BAG

CAMERA = "t265_fisheye1_optical_frame"
TAGS = "/t265/fisheye1/tags"
ODOM = "/vio_node/odom"
#: tagslam.yaml: T_body_odom, position and rotation vector (rad), between the rig (cam0's optical
#: frame) and the odometry's frame (Basalt's IMU).
T_BODY_ODOM_XYZ = np.array([0.010699568316340447, 0.0, 0.0])
T_BODY_ODOM_ROTVEC = np.array([0.0135696, -0.0062165, 3.1391944])


def stairs_chain(realdata: Path, *, as_tagslam_applies_it: bool = True) -> ChainConfig:
    """The chain TagSLAM's files describe. TagSLAM uses T_body_odom as p_body = T_body_odom p_odom,
    so the camera sits in the odometry frame at its inverse; ``False`` puts the numbers on the edge as
    written."""
    rotation = Rotation.from_rotvec(T_BODY_ODOM_ROTVEC)
    if as_tagslam_applies_it:
        rotation, xyz = rotation.inv(), -rotation.inv().apply(T_BODY_ODOM_XYZ)
    else:
        xyz = T_BODY_ODOM_XYZ
    sizes: dict[Any, float] = {"default": 0.16}
    bodies = yaml.safe_load((realdata / STAIRS / "tagslam.yaml").read_text())["bodies"]
    for tag in bodies[0]["house"]["tags"]:
        sizes[int(tag["id"])] = float(tag["size"])
    return ChainConfig.from_dict({
        "frames": {"camera": CAMERA, "body": "basalt_pose_frame", "world": "world"},
        "topics": {"detections": TAGS, "odometry": ODOM},
        "calibration": {"file": str(realdata / STAIRS / "cameras.yaml"), "camera": "cam0"},
        "mounts": [{"parent": "basalt_pose_frame", "child": CAMERA, "xyz": [float(v) for v in xyz],
                    "rotvec": [float(v) for v in rotation.as_rotvec()]}],
        "evidence": {"static_target": True, "tag_size_m": sizes},
    })


@cache
def recorded_attribution(realdata: Path) -> Attribution:
    """The bag through the tutorial's chain (the mount as TagSLAM applies it), attributed once per process: several
    tests of the stairs, the bounds, the verdicts and static targets read it (an Attribution is frozen)."""
    chain = stairs_chain(realdata)
    return pipeline.run(realdata / STAIRS_BAG, chain, bootstrap=0).attributed()


def restamped_bag(realdata: Path, shifted: Path, shift_ns: int) -> Path:
    """A copy of the bag with the odometry's header stamps moved by ``shift_ns`` (rosbags' own writer)."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    with AnyReader([realdata / STAIRS_BAG]) as reader, Writer(shifted) as writer:
        out = {c.id: writer.add_connection(c.topic, c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest)
               for c in reader.connections}
        for conn, t, raw in reader.messages():
            data = raw
            if conn.topic == ODOM:
                msg = reader.deserialize(raw, conn.msgtype)
                stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec + shift_ns
                msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 10**9)
                data = store.serialize_ros1(msg, conn.msgtype)
            writer.write(out[conn.id], t, data)
    return shifted
