"""open_dataset: a LeRobot episode as a Timeline, replayed; wrist camera, latency, depth, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from framechain import pipeline
from framechain.adapters.lerobot.adapter import open_dataset
from framechain.adapters.lerobot.reader import DatasetError
from framechain.analysis.model.estimates import estimate_to_json
from framechain.catalogue import HopName
from framechain.config.chain import ChainConfig, ChainEvidence, ChainFrames
from framechain.config.robot import RobotConfig, RobotConfigError
from framechain.replay import TransformBuffer, replay
from framechain.timeline import Timeline
from tests.helpers.lerobot_scene import (
    ARM_JOINTS,
    FINGER_UPPER_M,
    ArmDataset,
    base_from_optical_truth,
    episode_times,
    state_vectors,
    target_world,
    world_from_base,
    write_arm_dataset,
    write_detection_table,
    write_robot_yaml,
)

FRAMES = ChainFrames(camera="wrist_optical_frame", body="base_link", world="world")


def _hop_gaps(result: object, hop: HopName) -> np.ndarray:
    hops = result.hops  # type: ignore[attr-defined]
    return np.asarray(hops.gap_ns[hops.hop == hop.value])


def test_timeline_tables(arm_dataset: ArmDataset, tmp_path: Path) -> None:
    robot = write_robot_yaml(tmp_path, detections=[{"feature": "observation.detection.wrist", "camera": "wrist"}])
    tl = open_dataset(arm_dataset.root, episode=1, robot=robot)
    t = arm_dataset.timestamps[1]
    stamps = np.round(t * 1e9).astype(np.int64)
    tf = tl.transforms
    static = set(zip(tf.parent[tf.is_static].tolist(), tf.child[tf.is_static].tolist(), strict=True))
    assert static == {("world", "base_link"), ("flange_link", "tool_link"), ("flange_link", "wrist_camera_link"),
                      ("flange_link", "wrist_link"), ("wrist_link", "wrist_optical_frame")}
    dynamic = tf.take(~tf.is_static)
    for child in ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "flange_link",
                  "finger_left_link", "finger_right_link"):
        np.testing.assert_array_equal(dynamic.stamp_ns[dynamic.child == child], stamps)
    # Joint states in SI: degrees -> radians, 0-100 -> the finger's limits.
    stored = state_vectors(t).astype(np.float32).astype(np.float64)
    wide_stamps, wide = tl.joint_states.wide([*ARM_JOINTS, "finger_left"])
    np.testing.assert_array_equal(wide_stamps, stamps)
    np.testing.assert_allclose(wide[:, :6], stored[:, :6] * np.pi / 180.0, atol=1e-15)
    np.testing.assert_allclose(wide[:, 6], stored[:, 6] / 100.0 * FINGER_UPPER_M, atol=1e-15)
    # Observations: every frame with a detection (every fifth is NaN), stamped at the frame time.
    obs = tl.observations
    assert len(obs) == 40 - 8
    keep = np.ones(40, dtype=bool)
    keep[::5] = False
    np.testing.assert_array_equal(obs.stamp_ns, stamps[keep])
    np.testing.assert_array_equal(obs.log_time_ns, stamps[keep])
    assert set(obs.camera_frame.tolist()) == {"wrist_optical_frame"}
    assert len(tl.cameras) == 1
    meta = tl.metadata
    assert meta["format"] == "lerobot"
    assert meta["episode"] == 1
    assert meta["length"] == 40
    assert meta["source"]["format"] == "lerobot"
    assert meta["chain_frames"] == {"camera": "wrist_optical_frame", "body": "base_link", "world": "world"}
    json.dumps(dict(meta))
    # Replay: every detection lands on the static target.
    result = replay(tl, FRAMES)
    assert result.counts() == {"total": 32, "replayed": 32, "rejected": {}, "stale": 0}
    np.testing.assert_allclose(result.p_world, np.tile(target_world(), (32, 1)), atol=1e-5)


def test_wrist_camera_extrinsic_follows_the_joint_state(arm_dataset: ArmDataset, tmp_path: Path) -> None:
    tl = open_dataset(arm_dataset.root, episode=2, robot=write_robot_yaml(tmp_path))
    t = arm_dataset.timestamps[2]
    buf = TransformBuffer.from_timeline(tl)
    got = buf.lookup("base_link", "wrist_optical_frame", np.round(t * 1e9).astype(np.int64))
    truth = base_from_optical_truth(t, stored=True)
    from scipy.spatial.transform import Rotation

    np.testing.assert_allclose(got.translation, truth[:, :3, 3], atol=1e-12)
    np.testing.assert_allclose(Rotation.from_quat(got.quat_xyzw).as_matrix(), truth[:, :3, :3], atol=1e-12)
    world = buf.lookup("world", "base_link", np.round(t * 1e9).astype(np.int64))
    np.testing.assert_allclose(world.translation[0], world_from_base()[:3, 3], atol=1e-15)
    # The camera moves: the extrinsic is not one static value.
    assert np.ptp(got.translation, axis=0).max() > 1e-3


@pytest.mark.parametrize(("suffix", "by"), [(".parquet", "frame_index"), (".csv", "frame_index"),
                                            (".parquet", "timestamp")])
def test_side_table_detections(arm_dataset: ArmDataset, tmp_path: Path, suffix: str, by: str) -> None:
    table = tmp_path / f"detections{suffix}"
    n = write_detection_table(table, arm_dataset, 1, by=by, other_episode=0)
    robot = write_robot_yaml(tmp_path, detections=[{"table": table.name}])
    tl = open_dataset(arm_dataset.root, episode=1, robot=robot)
    assert len(tl.observations) == n
    assert set(tl.observations.label.tolist()) == {"cup"}
    np.testing.assert_allclose(tl.observations.score, 0.9)
    result = replay(tl, FRAMES)
    assert result.counts()["replayed"] == n
    np.testing.assert_allclose(result.p_world, np.tile(target_world(), (n, 1)), atol=1e-6)


def test_detections_passed_as_argument(arm_dataset: ArmDataset, tmp_path: Path) -> None:
    table = tmp_path / "det.parquet"
    n = write_detection_table(table, arm_dataset, 0)
    tl = open_dataset(arm_dataset.root, episode=0, robot=write_robot_yaml(tmp_path), detections=table)
    assert len(tl.observations) == n


@pytest.mark.parametrize("how", ["timestamp_column", "offset_s"])
def test_injected_camera_latency_is_the_gap_per_observation(tmp_path: Path, how: str) -> None:
    delay = 0.012
    ds = write_arm_dataset(tmp_path / "ds", version="v3.0", lengths=(45,), camera_delay_s=delay,
                           camera_timestamp_column=how == "timestamp_column")
    n = write_detection_table(tmp_path / "det.parquet", ds, 0)
    timing = ({"timestamp_column": "observation.images.wrist.timestamp"} if how == "timestamp_column"
              else {"offset_s": delay})
    robot = write_robot_yaml(tmp_path, timing=timing, detections=[{"table": "det.parquet"}])
    tl = open_dataset(ds.root, episode=0, robot=robot)
    obs = tl.observations
    gap = obs.stamp_ns - obs.log_time_ns
    if how == "offset_s":
        np.testing.assert_array_equal(gap, 12_000_000)
    else:  # float64 camera times against float32 frame times
        np.testing.assert_allclose(gap, 12_000_000, atol=2_000)
    strict = replay(tl, FRAMES, latency_budget_s=0.005)
    np.testing.assert_allclose(_hop_gaps(strict, HopName.CAMERA_TO_BODY), gap, atol=0)
    np.testing.assert_array_equal(_hop_gaps(strict, HopName.BODY_TO_WORLD), 0)
    # The last detection (frame 44) was taken 12 ms after the last joint state: an extrapolation.
    assert strict.counts() == {"total": n, "replayed": n - 1, "rejected": {"extrapolation": 1}, "stale": n - 1}
    assert strict.status[-1] == "extrapolation"
    assert replay(tl, FRAMES, latency_budget_s=0.02).counts()["stale"] == 0
    # Looked up at the camera's time, the chain lands on the target (up to interpolating 30 Hz FK).
    err = np.linalg.norm(strict.p_world[:-1] - target_world(), axis=1)
    assert err.max() < 2e-4


def test_variable_rate_state_and_camera_times(tmp_path: Path) -> None:
    ds = write_arm_dataset(tmp_path / "ds", version="v2.1", lengths=(60,), camera_delay_s=0.01,
                           camera_timestamp_column=True, jitter_s=0.006, seed=3)
    frames = np.arange(2, 58, 3)
    write_detection_table(tmp_path / "det.parquet", ds, 0, frames=frames)
    robot = write_robot_yaml(tmp_path, timing={"timestamp_column": "observation.images.wrist.timestamp"},
                             detections=[{"table": "det.parquet"}])
    tl = open_dataset(ds.root, episode=0, robot=robot)
    assert any("variable rate" in note for note in tl.metadata["notes"])
    state_ns = np.round(ds.timestamps[0] * 1e9).astype(np.int64)
    cam_ns = np.round(ds.camera_times[0] * 1e9).astype(np.int64)
    np.testing.assert_array_equal(np.unique(tl.joint_states.stamp_ns), state_ns)
    np.testing.assert_array_equal(tl.observations.stamp_ns, cam_ns[frames])
    np.testing.assert_array_equal(tl.observations.log_time_ns, state_ns[frames])
    result = replay(tl, FRAMES, latency_budget_s=0.02)
    # The hop gap is against the nearest joint-state sample, whichever frame it belongs to.
    nearest = np.abs(cam_ns[frames][:, None] - state_ns[None, :]).argmin(axis=1)
    np.testing.assert_array_equal(_hop_gaps(result, HopName.CAMERA_TO_BODY), cam_ns[frames] - state_ns[nearest])
    assert np.linalg.norm(result.p_world - target_world(), axis=1).max() < 3e-4


def test_unrecorded_camera_latency_is_attributed(tmp_path: Path) -> None:
    delay = 0.04
    ds = write_arm_dataset(tmp_path / "ds", version="v2.1", lengths=(90,), camera_delay_s=delay)
    # Detections away from the episode's ends: the latency fit looks the camera up at +-0.25 s.
    write_detection_table(tmp_path / "det.parquet", ds, 0, frames=np.arange(14, 77, 2))
    robot = write_robot_yaml(tmp_path, detections=[{"table": "det.parquet"}])
    tl = open_dataset(ds.root, episode=0, robot=robot)
    naive = replay(tl, FRAMES)
    assert np.linalg.norm(naive.p_world - target_world(), axis=1).max() > 5e-3
    chain = ChainConfig(frames=FRAMES, evidence=ChainEvidence(reference_point=tuple(target_world()),
                                                              static_target=True))
    result = pipeline.run(tl, chain, bootstrap=5).attributed()
    assert result.findings, "no fault found"
    top = result.findings[0]
    assert (top.fault.value, top.hop) == ("latency", HopName.CAMERA_TO_BODY)
    assert estimate_to_json(top.estimate)["offset_s"] == pytest.approx(delay, abs=2e-3)


def test_depth_from_a_dataset_feature(tmp_path: Path) -> None:
    ds = write_arm_dataset(tmp_path / "ds", version="v3.0", lengths=(20,), detection_feature=True, depth=True)
    robot = write_robot_yaml(tmp_path, depth_camera=True)
    # The detection feature's pixels are for the 640x480 camera: scale them to the 64x48 depth camera,
    # and drop their depth so that it comes from the depth images.
    import pyarrow as pa
    import pyarrow.parquet as pq

    frames = pq.read_table(ds.root / "data" / "chunk-000" / "file-000.parquet",
                           columns=["frame_index", "observation.detection.wrist"])
    det = np.asarray(frames.column(1).to_pylist(), dtype=float)
    rows = np.flatnonzero(np.isfinite(det[:, 0]))
    pq.write_table(
        pa.table({"frame_index": rows, "camera": ["wrist"] * rows.size,
                                     "u": det[rows, 0] * 0.1, "v": det[rows, 1] * 0.1}),
        tmp_path / "det.parquet",
    )
    tl = open_dataset(ds.root, episode=0, robot=robot, detections=tmp_path / "det.parquet")
    depth = tl.depth_frames
    assert len(depth) == 20
    assert set(depth.encoding.tolist()) == {"16UC1"}
    assert depth.load(3).dtype == np.float32
    assert depth.load(3).shape == (48, 64)
    assert np.isnan(tl.observations.depth_m).all()
    result = replay(tl, FRAMES)
    assert result.counts()["replayed"] == rows.size
    np.testing.assert_allclose(result.depth_m, det[rows, 2], atol=6e-4)  # millimetre depth images
    assert np.linalg.norm(result.p_world - target_world(), axis=1).max() < 2e-3


def test_timeline_saves_and_loads(arm_dataset: ArmDataset, tmp_path: Path) -> None:
    robot = write_robot_yaml(tmp_path, detections=[{"feature": "observation.detection.wrist", "camera": "wrist"}])
    tl = open_dataset(arm_dataset.root, episode=0, robot=robot)
    tl.save(tmp_path / "saved")
    back = Timeline.load(tmp_path / "saved")
    # TransformTable re-normalises quaternions when built, which may move them by one ulp.
    np.testing.assert_allclose(back.transforms.quat_xyzw, tl.transforms.quat_xyzw, rtol=0, atol=1e-15)
    assert back.replace(transforms=tl.transforms).equals(tl)


def test_so101_dataset_with_a_wrist_camera(so101_urdf: Path, tmp_path: Path, rng: np.random.Generator) -> None:
    import yourdfpy

    from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset

    joints = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
    names = [f"{j}.pos" for j in joints]
    n = 15
    state = np.hstack([rng.uniform(-60, 60, size=(n, 5)), rng.uniform(0, 100, size=(n, 1))]).astype(np.float32)
    root = write_lerobot_dataset(tmp_path / "so101", [EpisodeData({"observation.state": state})],
                                 features={"observation.state": FeatureSpec("float32", (6,), names)}, fps=30,
                                 version="v3.0")
    cfg = {
        "urdf": str(so101_urdf), "default_unit": "deg",
        "joints": {**{f"{j}.pos": j for j in joints[:5]}, "gripper.pos": {"joint": "gripper", "unit": "range_0_100"}},
        "cameras": {"wrist": {"intrinsics": {"fx": 400, "fy": 400, "cx": 320, "cy": 240, "width": 640, "height": 480},
                              "mount": {"parent": "gripper_link", "xyz": [0.0, -0.05, -0.03],
                                        "quat_xyzw": [0.0, 0.0, 0.0, 1.0], "optical": True}}},
    }
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(cfg))
    tl = open_dataset(root, episode=0, robot=tmp_path / "robot.yaml")
    buf = TransformBuffer.from_timeline(tl)
    stamps = np.round(episode_times(0, n) * 1e9).astype(np.int64)  # the writer's float32 frame times
    got = buf.lookup("base_link", "wrist_optical_frame", stamps)
    ref = yourdfpy.URDF.load(str(so101_urdf), load_meshes=False, build_collision_scene_graph=False)
    lo, hi = ref.joint_map["gripper"].limit.lower, ref.joint_map["gripper"].limit.upper
    mount = np.eye(4)
    mount[:3, 3] = [0.0, -0.05, -0.03]
    for i in range(n):
        cfg_i = {j: float(state[i, k]) * np.pi / 180 for k, j in enumerate(joints[:5])}
        cfg_i["gripper"] = lo + float(state[i, 5]) / 100 * (hi - lo)
        ref.update_cfg(cfg_i)
        expected = ref.get_transform(frame_to="gripper_link", frame_from="base_link") @ mount
        np.testing.assert_allclose(got.translation[i], expected[:3, 3], atol=1e-12)


# ------------------------------------------------------------------------------------- errors


def test_configuration_errors(arm_dataset: ArmDataset, tmp_path: Path) -> None:
    robot = write_robot_yaml(tmp_path)
    raw = yaml.safe_load(robot.read_text())
    # A camera below a joint no state drives.
    partial = {**raw, "joints": {k: v for k, v in raw["joints"].items() if k != "wrist_roll.pos"}}
    with pytest.raises(RobotConfigError, match=r"camera 'wrist' hangs below joints \['wrist_roll'\] that no "
                                                r"dataset state drives"):
        open_dataset(arm_dataset.root, episode=0, robot=RobotConfig.from_mapping(partial, base_dir=tmp_path))
    # Holding it fixed is explicit and fine.
    held = RobotConfig.from_mapping({**partial, "hold": {"wrist_roll": 0.2}}, base_dir=tmp_path)
    tl = open_dataset(arm_dataset.root, episode=0, robot=held)
    assert tl.metadata["held_joints"] == {"wrist_roll": 0.2}
    renamed = {**raw, "joints": {**raw["joints"], "elbow.pos": raw["joints"]["elbow_flex.pos"]}}
    del renamed["joints"]["elbow_flex.pos"]
    with pytest.raises(RobotConfigError, match=r"state names \['elbow.pos'\] are not in observation.state; "
                                               r"it has \['shoulder_pan.pos'"):
        open_dataset(arm_dataset.root, episode=0, robot=RobotConfig.from_mapping(renamed, base_dir=tmp_path))
    calib = yaml.safe_load((tmp_path / "calib" / "wrist.yaml").read_text())
    video_depth = {**raw, "cameras": {"wrist": {**calib, "depth": {"feature": "observation.images.wrist"}}}}
    with pytest.raises(DatasetError, match=r"depth feature 'observation.images.wrist' of camera 'wrist' is a "
                                           r"video: framechain does not decode images"):
        open_dataset(arm_dataset.root, episode=0, robot=RobotConfig.from_mapping(video_depth, base_dir=tmp_path))
    with pytest.raises(DatasetError, match=r"no feature 'observation.joint_pos'"):
        open_dataset(arm_dataset.root, episode=0,
                     robot=RobotConfig.from_mapping({**raw, "state_feature": "observation.joint_pos"},
                                                    base_dir=tmp_path))


def test_detection_table_errors(arm_dataset: ArmDataset, tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    robot = write_robot_yaml(tmp_path, detections=[{"table": "det.parquet"}])
    pq.write_table(pa.table({"frame_index": [0], "camera": ["head"], "u": [1.0], "v": [2.0]}), tmp_path / "det.parquet")
    with pytest.raises(DatasetError, match=r"det.parquet: detections name cameras \['head'\] that robot.yaml does "
                                           r"not calibrate"):
        open_dataset(arm_dataset.root, episode=0, robot=robot)
    pq.write_table(pa.table({"frame_index": [99], "u": [1.0], "v": [2.0]}), tmp_path / "det.parquet")
    with pytest.raises(DatasetError, match=r"frame_index must be integers in 0..23 for episode 0"):
        open_dataset(arm_dataset.root, episode=0, robot=robot)
    pq.write_table(pa.table({"frame_index": [1], "u": [1.0]}), tmp_path / "det.parquet")
    with pytest.raises(DatasetError, match=r"detections table has no 'v' column"):
        open_dataset(arm_dataset.root, episode=0, robot=robot)


# ----------------------------------------------------------------------------------- real data


def _left_arm_urdf(path: Path, names: list[str]) -> None:
    """A made-up serial chain whose joints carry the Unitree state names (the G1 URDF is not here)."""
    links = "".join(f'<link name="l{i}"/>' for i in range(len(names) + 1))
    joints = "".join(
        f'<joint name="{n}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
        f'<origin xyz="0.1 0 0" rpy="0 0 0"/><axis xyz="0 {i % 2} {1 - i % 2}"/>'
        f'<limit lower="-3" upper="3"/></joint>'
        for i, n in enumerate(names)
    )
    path.write_text(f'<?xml version="1.0"?><robot name="left_arm">{links}{joints}</robot>')


def test_unitree_episode_opens_through_a_robot_config(unitree: Path, tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    names = json.loads((unitree / "meta" / "info.json").read_text())["features"]["observation.state"]["names"][0]
    arm = names[:7]
    _left_arm_urdf(tmp_path / "arm.urdf", arm)
    cfg = RobotConfig.from_mapping({
        "urdf": "arm.urdf", "default_unit": "rad", "joints": {n: n for n in arm},
        "cameras": {"head": {"intrinsics": {"fx": 300, "fy": 300, "cx": 320, "cy": 240, "width": 640, "height": 480},
                             "mount": {"parent": "l7", "xyz": [0.05, 0, 0], "rpy": [0, 0, 0], "optical": False},
                             "video_key": "observation.images.cam_high"}},
    }, base_dir=tmp_path)
    tl = open_dataset(unitree, episode=5, robot=cfg)
    raw = np.asarray(pq.read_table(unitree / "data" / "chunk-000" / "episode_000005.parquet",
                                   columns=["observation.state"]).column(0).to_pylist(), dtype=np.float32)
    _, wide = tl.joint_states.wide(arm)
    np.testing.assert_array_equal(wide, raw[:, :7].astype(np.float64))
    assert tl.metadata["cameras"]["head"]["video_file"] is None  # videos are not in the sample
    assert any("'observation.images.cam_high' is declared but no video files" in n for n in tl.metadata["notes"])


def test_real_datasets_fail_with_clear_messages(unitree: Path, gr00t: Path, tmp_path: Path) -> None:
    robot = write_robot_yaml(tmp_path)
    with pytest.raises(RobotConfigError, match=r"state names \['shoulder_pan.pos', .*\] are not in "
                                               r"observation.state; it has \['kLeftShoulderPitch'"):
        open_dataset(unitree, episode=0, robot=robot)
    with pytest.raises(DatasetError, match=r"gr00t_pick_n_place_v20/meta/info.json: total_chunks is 0 but data/ "
                                           r"holds 1 chunk folders"):
        open_dataset(gr00t, episode=0, robot=robot, strict=True)
    raw = yaml.safe_load(robot.read_text())
    raw["cameras"] = {"ego": {**yaml.safe_load((tmp_path / "calib" / "wrist.yaml").read_text()),
                              "video_key": "observation.images.egoview"}}
    raw["cameras"]["ego"].pop("name")
    with pytest.raises(RobotConfigError, match=r"state names \['shoulder_pan.pos'.*it has \['motor_0'"):
        open_dataset(gr00t, episode=0, robot=RobotConfig.from_mapping(raw, base_dir=tmp_path))
