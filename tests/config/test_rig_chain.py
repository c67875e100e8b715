"""A chain of several cameras: the ``cameras:`` list, ``evidence.moving_labels``, a rig without a pose or fixed in
the world, and the rig calibration files (TagSLAM camera_poses.yaml, a Kalibr camchain) checked against scipy."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.config.chain import ChainConfig
from framechain.config.errors import ChainConfigError
from framechain.config.rig_poses import rig_camera_poses
from tests.helpers.realdata import QUAD_RIG

RIG: dict[str, Any] = {
    "frames": {"body": "rig", "world": "arena"},
    "cameras": [
        {"frame": "cam_sync/cam0", "detections": "/cam_sync/cam0/tags", "calibration": {"file": "cameras.yaml",
                                                                                      "camera": "cam0"}},
        {"frame": "cam_sync/cam1", "detections": "/cam_sync/cam1/tags", "calibration": {"file": "cameras.yaml",
                                                                                      "camera": "cam1"},
         "camera_info": "/cam1/info", "image": "/cam1/image", "depth": "/cam1/depth", "latency_budget_s": 0.05},
    ],
    "mounts": [{"parent": "rig", "child": "cam_sync/cam1", "xyz": [0.1, 0, 0], "rotvec": [0, 0, 0.1]}],
    "evidence": {"static_target": True, "moving_labels": [0, 1, 2, 3, 4], "tag_size_m": {"default": 0.12, 0: 0.11986}},
}


def test_a_two_camera_rig_chain_reads_with_its_per_camera_keys_and_round_trips() -> None:
    chain = ChainConfig.from_dict(RIG)
    assert chain.is_rig
    assert chain.camera_frames() == ("cam_sync/cam0", "cam_sync/cam1")
    assert chain.frames.camera == "cam_sync/cam0"
    assert (chain.frames.body, chain.frames.world, chain.has_pose) == ("rig", "arena", True)
    assert chain.evidence.moving_labels == ("0", "1", "2", "3", "4")
    assert chain.evidence.tag_size_m == {"default": 0.12, "0": 0.11986}
    assert chain.topic_frames() == {"/cam_sync/cam0/tags": "cam_sync/cam0", "/cam_sync/cam1/tags": "cam_sync/cam1",
                                    "/cam1/info": "cam_sync/cam1", "/cam1/image": "cam_sync/cam1",
                                    "/cam1/depth": "cam_sync/cam1"}
    assert [(c.camera, c.frame) for c in chain.calibration_sources()] == [("cam0", "cam_sync/cam0"),
                                                                          ("cam1", "cam_sync/cam1")]
    assert chain.latency_budget_for("cam_sync/cam1") == 0.05
    assert chain.latency_budget_for("cam_sync/cam0") == chain.latency_budget_s
    assert chain.mounts[0].form == "rotvec"
    assert ChainConfig.from_dict(chain.to_dict()) == chain


def test_no_world_is_a_rig_without_pose_and_world_as_body_a_fixed_rig() -> None:
    free = ChainConfig.from_dict({**RIG, "frames": {"body": "rig"}})
    assert not free.has_pose
    assert free.frames.world == "rig"
    assert "world" not in free.to_dict()["frames"]
    assert ChainConfig.from_dict(free.to_dict()) == free
    fixed = ChainConfig.from_dict({**RIG, "frames": {"body": "arena", "world": "arena"}})
    assert fixed.has_pose
    assert fixed.frames.world == fixed.frames.body == "arena"


@pytest.mark.parametrize(("change", "message"), [
    ({"topics": {"detections": "/tags"}}, "topics.detections: a rig chain gives these per camera"),
    ({"cameras": []}, "cameras: expected a list of cameras"),
    ({"cameras": [{"frame": "a"}]}, "cameras[0]: missing detections"),
    ({"cameras": [{"frame": "a", "detections": "/t"}, {"frame": "a", "detections": "/u"}]},
     "cameras[1] and cameras[0] have the same frame 'a'"),
    ({"cameras": [{"frame": "a", "detections": "/t", "colour": 1}]}, "cameras[0]: unknown keys ['colour']"),
    ({"frames": {"body": "cam_sync/cam0"}}, "must not be camera frames of the rig"),
    ({"frames": {"body": "rig", "camera": "other"}}, "camera 'other' is none of the rig's cameras"),
    ({"evidence": {"ignore_labels": [1], "moving_labels": [1, 2]}}, "labels ['1'] are both in ignore_labels"),
    ({"cameras": [{"frame": "a", "detections": "/t", "calibration": {"file": "c.yaml", "frame": "b"}}]},
     "cameras[0].calibration: unknown keys ['frame']"),
    ({"cameras": [{"frame": "a", "detections": "/t", "latency_budget_s": 50}]}, "latency_budget_s"),
])
def test_a_bad_rig_is_one_line_naming_the_key(change: dict[str, Any], message: str) -> None:
    with pytest.raises(ChainConfigError, match=None) as err:
        ChainConfig.from_dict({**RIG, **change}, where="rig.yaml")
    text = str(err.value)
    assert message in text
    assert "\n" not in text
    assert text.startswith("rig.yaml")


def test_tagslam_camera_poses_are_t_rig_cam(realdata: Path) -> None:
    raw = yaml.safe_load((realdata / QUAD_RIG / "camera_poses.yaml").read_text())
    poses = rig_camera_poses(raw)
    assert sorted(poses) == ["cam0", "cam1", "cam2", "cam3"]
    for name, (xyz, quat) in poses.items():
        pose = raw[name]["pose"]
        assert xyz == pytest.approx([pose["position"][a] for a in "xyz"])
        expected = Rotation.from_rotvec([pose["rotation"][a] for a in "xyz"])
        assert (Rotation.from_quat(quat).inv() * expected).magnitude() < 1e-9


def test_kalibr_camchain_chains_t_cn_cnm1_from_the_first_camera() -> None:
    rng = np.random.default_rng(5)
    truth = [np.eye(4)]
    for _ in range(2):  # T_rig_cam of cam1 and cam2, random
        m = np.eye(4)
        m[:3, :3] = Rotation.from_rotvec(rng.normal(0, 0.5, 3)).as_matrix()
        m[:3, 3] = rng.normal(0, 0.2, 3)
        truth.append(m)
    camchain: dict[str, Any] = {}
    for i in range(3):
        entry: dict[str, Any] = {"intrinsics": [500, 500, 320, 240], "resolution": [640, 480]}
        if i:  # T_cn_cnm1 maps points of camera n-1 into camera n
            entry["T_cn_cnm1"] = (np.linalg.inv(truth[i]) @ truth[i - 1]).tolist()
        camchain[f"cam{i}"] = entry
    poses = rig_camera_poses(camchain)
    for i in range(3):
        xyz, quat = poses[f"cam{i}"]
        assert np.allclose(xyz, truth[i][:3, 3], atol=1e-9)
        assert np.allclose(Rotation.from_quat(quat).as_matrix(), truth[i][:3, :3], atol=1e-9)


def test_the_quad_rig_log_suggests_its_rig_chain(realdata: Path) -> None:
    folder = realdata / QUAD_RIG
    loaded = pipeline.load_log(folder / "tag_detections.bag")
    chain = loaded.chain
    assert loaded.chain_suggested
    assert loaded.suggestion is not None
    assert loaded.suggestion.ready
    # Frames after the topics (the headers are permuted), in cameras.yaml's order, calibrated by it.
    assert chain.camera_frames() == ("quadruple/bottom_left", "quadruple/bottom_right", "quadruple/top_left",
                                     "quadruple/top_right")
    assert [c.calibration.camera for c in chain.cameras if c.calibration] == ["cam0", "cam1", "cam2", "cam3"]
    assert not chain.has_pose
    assert chain.evidence.tag_size_m == {"default": 0.125, "44": 0.15}
    raw = yaml.safe_load((folder / "camera_poses.yaml").read_text())
    for camera, mount in zip(["cam0", "cam1", "cam2", "cam3"], chain.mounts, strict=True):
        pose = raw[camera]["pose"]
        assert mount.parent == "rig"
        assert mount.xyz == pytest.approx([pose["position"][a] for a in "xyz"])
        rotvec = Rotation.from_quat(mount.quat_xyzw).as_rotvec()
        assert np.allclose(rotvec, [pose["rotation"][a] for a in "xyz"], atol=1e-7)
    text = loaded.suggestion.to_yaml()
    again = ChainConfig.from_dict(yaml.safe_load(text), base_dir=folder)
    assert again.camera_frames() == chain.camera_frames()
    assert np.allclose([m.xyz for m in again.mounts], [m.xyz for m in chain.mounts])
    counts = {f: int((loaded.timeline.observations.camera_frame == f).sum()) for f in chain.camera_frames()}
    assert counts == {"quadruple/bottom_left": 3833, "quadruple/bottom_right": 4884, "quadruple/top_left": 1882,
                      "quadruple/top_right": 4056}
