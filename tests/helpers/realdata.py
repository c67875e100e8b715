"""The real logs beside the checkout (``../shared/realdata``, never copied into the project), each path named once.

Tests take the folder from the ``realdata`` fixture (tests/conftest.py), which skips the test when the folder is
absent, and join a name from here to it: ``realdata / STAIRS_BAG``. The names are relative to the folder, so no test
reaches a real log past that skip.
"""

from __future__ import annotations

from pathlib import Path

#: The folder itself, for the ``realdata`` fixture and for scripts run outside pytest: ``shared/realdata`` beside the
#: checkout (tests/helpers/realdata.py is three levels below the checkout's parent).
REALDATA = Path(__file__).resolve().parents[3] / "shared" / "realdata"

# ROS logs: ROS 1 bags, ROS 2 bag folders, MCAP.
TF_EXAMPLE_BAG = "evo/tf_example.bag"
TF_EXAMPLE_ROS2 = "evo/tf_example"
NAV2_MCAP = "evo/nav2_turtlebot.mcap"
ARUCO_IMAGES_BAG = "fiducials/aruco_images.bag"
ARUCO_MARKER_BAG = "fiducials/aruco_marker.bag"
FRANKA_BAG = "franka_tf/rosbagFrankaPanda.bag"
FRANKA_ROS2 = "franka_tf/ros2_bag"
HUSKY_BAG = "husky_localization/test1.bag"
HUSKY_OLD_FRAMES_BAG = "husky_localization/test1_old_stereo_wheel.bag"
TURTLESIM_BAG = "turtlesim/example.bag"
REALSENSE_BAG = "realsense_d435/test_rs.bag"
#: TagSLAM's stairs log, with the files that describe it beside it (cameras.yaml, tagslam.yaml, camera_poses.yaml).
STAIRS = "tagslam_stairs"
STAIRS_BAG = f"{STAIRS}/tag_detections.bag"
#: TagSLAM's four-camera rig, with its files beside it as for the stairs.
QUAD_RIG = "tagslam_quad_rig"
QUAD_RIG_BAG = f"{QUAD_RIG}/tag_detections.bag"

#: Every ROS log in the folder.
ROS_LOGS = [
    TF_EXAMPLE_BAG, TF_EXAMPLE_ROS2, NAV2_MCAP, ARUCO_IMAGES_BAG, ARUCO_MARKER_BAG, FRANKA_BAG, FRANKA_ROS2,
    HUSKY_BAG, HUSKY_OLD_FRAMES_BAG, TURTLESIM_BAG, REALSENSE_BAG, STAIRS_BAG, QUAD_RIG_BAG,
]

# LeRobot datasets (the fixtures ``unitree`` and ``gr00t`` give their folders).
UNITREE = "lerobot/unitree_g1_v21"
GR00T = "lerobot/gr00t_pick_n_place_v20"
#: Every LeRobot dataset in the folder.
LEROBOT_DATASETS = [GR00T, UNITREE]

# Published URDFs (the fixture ``so101_urdf`` gives the SO-101's).
SO101_URDF = "urdf/so101/so101_new_calib.urdf"
KOCH_URDF = "urdf/koch/low-cost-arm.urdf"
PANDA_URDF = "urdf/panda/panda.urdf"

#: GoPro clips (karma.mp4, max-heromode.mp4) with their GPMF telemetry.
GOPRO_CLIPS = "gopro_gpmf"


def aruco_images_chain(
    evidence: dict[str, object], mount_quat_xyzw: tuple[float, ...] = (-0.5, 0.5, -0.5, 0.5)
) -> dict[str, object]:
    """A chain for the fiducials bag's one JPEG of seven ArUco markers (a Raspberry Pi camera on a base), as a
    ``ChainConfig.from_dict`` mapping with ``evidence`` as given and the camera's mount turned as given."""
    return {
        "frames": {"camera": "raspicam", "body": "base_link", "world": "map"},
        "topics": {"image": "/raspicam_node/image/compressed", "camera_info": "/raspicam_node/camera_info"},
        "mounts": [{"parent": "base_link", "child": "raspicam", "xyz": [0.1, 0, 0.3],
                    "quat_xyzw": list(mount_quat_xyzw)},
                   {"parent": "map", "child": "base_link", "xyz": [0, 0, 0], "rpy": [0, 0, 0]}],
        "evidence": evidence,
    }


def gopro_clip(realdata: Path, name: str) -> Path:
    """A GoPro clip of the shared folder (karma.mp4, max-heromode.mp4); the test is skipped when it is absent."""
    import pytest

    path = realdata / GOPRO_CLIPS / name
    if not path.is_file():
        pytest.skip(f"{path} not found")
    return path
