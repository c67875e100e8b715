"""A wrist camera's own motion, seen in generated SO-101 LeRobot episodes, against their known truth.

Episodes come from :mod:`framechain.sim.lerobot_video` (its own URDF maths and renderer, encoded
with PyAV, written as v3.0 and v2.1); the evidence runs the way the pipeline will: framechain's
dataset reader, video decoder, feature tracker, kinematics and fit (:mod:`tests.helpers.egomotion_scene`).
Every expectation is the generator's truth: the injected video delay, mount rotation and arm.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain.analysis.egomotion import EgoMotionFit, EgoMotionFitOptions, fit_camera_motion, translation_prior
from framechain.analysis.egomotion import fit as fit_module
from framechain.analysis.egomotion.joint import (
    GRID_HALF,
    GRID_STEP_S,
    MOUNT_STEP_DEG,
    Joint,
    Searched,
    _grid,
    _rotvecs_of,
    _Trials,
    finish_fit,
)
from framechain.cli.main import main
from framechain.config.calibration import Intrinsics
from framechain.geometry.rotations import RotationVector, quat_of
from framechain.sim.lerobot_video import (
    ARM_JOINTS,
    VideoDatasetSpec,
    VideoDatasetTruth,
    generate_video_dataset,
    gripper_pads,
    write_robot_yaml,
)
from framechain.sim.urdf_chain import UrdfChain
from framechain.timeline import EgoMotionTable, TranslationPrior
from framechain.vision.egomotion import measure_egomotion, track_features
from tests.helpers.egomotion_scene import EpisodeEvidence, episode_evidence, fit_episode, shifted_copy

DURATION_S = 5.0


def mount_error_deg(fit: EgoMotionFit, truth: VideoDatasetTruth) -> float:
    """The measured mount against the true one (generator's truth)."""
    return float(np.rad2deg((Rotation.from_quat(fit.q_link_cam).inv() * Rotation.from_quat(truth.q_link_cam))
                            .magnitude()))


@pytest.fixture(scope="session")
def faulted(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path
            ) -> tuple[VideoDatasetTruth, EpisodeEvidence, EgoMotionFit]:
    """v2.1: video 80 ms late, declared mount 10 degrees off, 10% of the frames resent."""
    spec = VideoDatasetSpec(so101_urdf, seed=11, duration_s=DURATION_S, version="v2.1", video_delay_s=0.080,
                            mount_error_deg=10.0, repeat_share=0.1)
    truth = generate_video_dataset(tmp_path_factory.mktemp("faulted") / "dataset", spec)
    evidence = episode_evidence(truth, so101_urdf)
    return truth, evidence, fit_episode(evidence, truth)


@pytest.fixture(scope="session")
def clean(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path
          ) -> tuple[VideoDatasetTruth, EpisodeEvidence, EgoMotionFit]:
    """v3.0, two episodes in one mp4: the second one's frames start 5 s into the file."""
    spec = VideoDatasetSpec(so101_urdf, seed=12, duration_s=DURATION_S, episodes=2, version="v3.0")
    truth = generate_video_dataset(tmp_path_factory.mktemp("clean") / "dataset", spec)
    evidence = episode_evidence(truth, so101_urdf, episode=1)
    return truth, evidence, fit_episode(evidence, truth)


def test_generator_kinematics_match_yourdfpy(so101_urdf: Path) -> None:
    import yourdfpy

    urdf = yourdfpy.URDF.load(str(so101_urdf), build_scene_graph=True, load_meshes=False)
    chain = UrdfChain(so101_urdf, prefix="left_")
    q = np.random.default_rng(0).uniform(-1.5, 1.5, (20, len(ARM_JOINTS)))
    ours = chain.root_from_link(dict(zip(ARM_JOINTS, q.T, strict=True)), "left_gripper_link")
    for i in range(q.shape[0]):
        urdf.update_cfg({**dict(zip(ARM_JOINTS, q[i], strict=True)), "gripper": 0.0})
        assert np.allclose(ours[i], urdf.get_transform(frame_to="gripper_link"), atol=1e-12)


def test_late_video_and_a_rotated_mount_are_measured(faulted: tuple[VideoDatasetTruth, EpisodeEvidence,
                                                                    EgoMotionFit]) -> None:
    truth, evidence, fit = faulted
    assert fit.link == truth.camera_link == "gripper_link"
    assert not fit.wrong_link
    assert fit.offset_s == pytest.approx(truth.expected_offset_s, abs=0.010)
    assert fit.offset_s == pytest.approx(-0.080, abs=0.010)
    assert fit.mount_error is not None
    assert fit.mount_error.angle_deg == pytest.approx(10.0, abs=1.0)
    axis = np.asarray(truth.spec.mount_error_axis) / np.linalg.norm(truth.spec.mount_error_axis)
    assert np.rad2deg(np.arccos(np.clip(np.dot(fit.mount_error.axis, axis), -1, 1))) < 10.0
    assert mount_error_deg(fit, truth) < 1.0
    assert fit.offset_observable
    assert fit.mount_observable
    assert fit.focal_scale == pytest.approx(1.0, abs=0.05)
    # The resent frames were found and left out of the motion.
    repeated = set(truth.repeated[0])
    assert set(evidence.health.duplicated) == repeated
    assert repeated
    assert not evidence.frames.usable[sorted(repeated)].any()


def test_a_clean_episode_shows_no_offset_and_no_mount_error(clean: tuple[VideoDatasetTruth, EpisodeEvidence,
                                                                         EgoMotionFit]) -> None:
    truth, evidence, fit = clean
    assert evidence.health.notes() == []
    assert evidence.frames.usable.all()
    assert len(evidence.stamps_ns) == int(DURATION_S * truth.spec.fps)
    assert fit.link == "gripper_link"
    assert not fit.wrong_link
    assert abs(fit.offset_s) < 0.010
    low, high = fit.offset_interval_s
    assert low <= 0.010
    assert high >= -0.010
    assert high - low < 0.020
    assert fit.mount_error is not None
    assert fit.mount_error.angle_deg < 1.0
    assert fit.mount_error.interval_deg[0] < 1.0
    assert mount_error_deg(fit, truth) < 1.0


def test_what_the_joint_fit_interpolates_is_what_measuring_gives(
        faulted: tuple[VideoDatasetTruth, EpisodeEvidence, EgoMotionFit]) -> None:
    """The joint fit measures at three offsets of a grid and interpolates the rest, and measures one mount step about
    each axis and takes the measurement as linear in the mount (joint.py): both against measuring again with the
    prior of that offset or mount, on real tracks."""
    truth, evidence, fit = faulted
    link = next(m for m in evidence.links if m.link == fit.link)

    def measure(prior: TranslationPrior | None, /, *, rotations_only: bool = False) -> EgoMotionTable:
        return measure_egomotion(evidence.tracks, evidence.stamps_ns, evidence.intrinsics, frame="wrist_optical_frame",
                                 translation=prior, rotations_only=rotations_only)

    trials = _Trials(measure, link, translation_prior, fit.q_link_cam, truth.xyz_link_cam, EgoMotionFitOptions())
    centre = fit.offset_s
    half = GRID_STEP_S * GRID_HALF  # a grid's half-width: its measurements are made at its ends and centre
    middle = trials.pairs(trials.table(centre))

    def rms_deg(a: np.ndarray, b: np.ndarray) -> float:
        ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
        return float(np.rad2deg(np.sqrt(((a[ok] - b[ok]) ** 2).sum(axis=1).mean())))

    for shift in (-0.008, -0.004, 0.004, 0.008):
        interpolated = trials.interpolated(centre + shift, (centre - half, centre + half))[0]
        measured = _rotvecs_of(trials.pairs(trials.table(centre + shift)), interpolated)
        moved = rms_deg(measured, _rotvecs_of(middle, interpolated))
        assert moved > 0.005  # the prior of another offset does move the measurement
        assert rms_deg(interpolated.rotvec, measured) < 0.1 * moved  # 2-4% measured
    turned = trials.turned(centre)
    for axis in np.eye(3):
        turn = -np.deg2rad(MOUNT_STEP_DEG) * axis  # the other side of the step measured
        predicted = turned(turn)
        mount = quat_of((trials.q_link_cam, RotationVector(turn)))
        measured = _rotvecs_of(trials.pairs(measure(translation_prior(link, mount, truth.xyz_link_cam, centre))),
                               predicted)
        moved = rms_deg(measured, _rotvecs_of(middle, predicted))
        assert moved > 0.002
        assert rms_deg(predicted.rotvec, measured) < 0.25 * moved  # 5-17% measured


def test_a_trial_measurement_has_the_complete_ones_rows_and_rotations(
        faulted: tuple[VideoDatasetTruth, EpisodeEvidence, EgoMotionFit]) -> None:
    """A fit's trials measure rotations only: the same rows, rotations and inlier counts as the complete measurement
    with that prior, which alone carries the translation directions, residuals and parallax."""
    truth, evidence, fit = faulted
    link = next(m for m in evidence.links if m.link == fit.link)
    prior = translation_prior(link, fit.q_link_cam, truth.xyz_link_cam, fit.offset_s)
    complete, trial = (measure_egomotion(evidence.tracks, evidence.stamps_ns, evidence.intrinsics, frame="wrist",
                                         translation=prior, rotations_only=only) for only in (False, True))
    assert len(trial) == len(complete) > 100
    for column in ("stamp0_ns", "stamp1_ns", "quat_xyzw", "tracks", "inliers"):
        np.testing.assert_array_equal(getattr(trial, column), getattr(complete, column))
    for column in ("residual_px", "parallax_px"):
        assert np.isfinite(getattr(complete, column)).all()
        assert np.isnan(getattr(trial, column)).all()
    assert np.isfinite(complete.direction).all(axis=1).mean() > 0.5  # most pairs show enough parallax here
    assert np.isnan(trial.direction).all()


def test_a_grid_at_the_window_edge_measures_nothing_beyond_it(
        faulted: tuple[VideoDatasetTruth, EpisodeEvidence, EgoMotionFit]) -> None:
    """Past the +-max_offset_s window the translation prior runs off the episode's ends: a grid clipped to the window
    interpolates between measurements inside it."""
    truth, evidence, fit = faulted
    link = next(m for m in evidence.links if m.link == fit.link)

    def measure(prior: TranslationPrior | None, /, *, rotations_only: bool = False) -> EgoMotionTable:
        return measure_egomotion(evidence.tracks, evidence.stamps_ns, evidence.intrinsics, frame="wrist_optical_frame",
                                 translation=prior, rotations_only=rotations_only)

    limit = 0.1
    trials = _Trials(measure, link, translation_prior, fit.q_link_cam, truth.xyz_link_cam,
                     EgoMotionFitOptions(max_offset_s=limit))
    grid, vertex = _grid(trials, -limit + 0.002, limit)
    assert grid.min() >= -limit
    assert grid.max() <= limit
    assert -limit <= vertex <= limit
    assert trials.tables
    assert all(abs(offset) <= limit for offset in trials.tables)


@pytest.fixture(scope="session")
def too_late(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> VideoDatasetTruth:
    """Video 0.6 s late, past the default +-0.5 s search window."""
    spec = VideoDatasetSpec(so101_urdf, seed=31, duration_s=DURATION_S, video_delay_s=0.6)
    return generate_video_dataset(tmp_path_factory.mktemp("too_late") / "dataset", spec)


def test_video_later_than_the_search_window_is_said_not_crashed(too_late: VideoDatasetTruth, so101_urdf: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """The offset lies at the window's edge and is said to be undetermined, with the key that widens the window (a
    grid piled on the edge once left the interval's resampling no spacing: an IndexError); no trial is measured
    beyond the window, though the rotation-only offset a search starts from lies past it."""
    offsets: list[float] = []
    measured = _Trials._measured

    def spy(self: _Trials, q_link_cam: np.ndarray, offset: float, *, rotations_only: bool) -> EgoMotionTable:
        offsets.append(offset)
        return measured(self, q_link_cam, offset, rotations_only=rotations_only)

    monkeypatch.setattr(_Trials, "_measured", spy)
    fit = fit_episode(episode_evidence(too_late, so101_urdf), too_late)
    assert len(offsets) > 10
    assert max(abs(offset) for offset in offsets) <= 0.5
    assert fit.offset_s == pytest.approx(-0.5, abs=0.005)
    assert "edge of the +-0.50 s search window" in fit.offset_undetermined
    assert "evidence.camera_offset_window_s widens it" in fit.offset_undetermined


def test_a_wider_search_window_from_robot_yaml_finds_it(too_late: VideoDatasetTruth, tmp_path: Path) -> None:
    """``chain: {evidence: {camera_offset_window_s: 1}}`` in robot.yaml: the command finds the 0.6 s."""
    robot = write_robot_yaml(too_late, tmp_path / "robot.yaml",
                             extra={"chain": {"evidence": {"camera_offset_window_s": 1.0}}})
    out = tmp_path / "out"
    assert main(["attribute", str(too_late.root), "--episode", "0", "--robot", str(robot), "--out", str(out),
                 "-q"]) == 0
    camera = json.loads((out / "attribution.json").read_text())["camera_motion"][0]
    assert camera["offset_s"] == pytest.approx(-0.6, abs=0.010)
    assert not camera["undetermined"]


def test_shifted_video_timestamps_move_the_offset(clean: tuple[VideoDatasetTruth, EpisodeEvidence, EgoMotionFit],
                                                  tmp_path: Path, so101_urdf: Path) -> None:
    truth, _evidence, fit = clean
    copy = shifted_copy(truth.root, tmp_path / "shifted", 0.100)
    shifted = episode_evidence(truth, so101_urdf, episode=1, root=copy)
    moved = fit_episode(shifted, truth)
    # Frames 100 ms later in the file: each row shows the scene 100 ms before its stamp.
    assert moved.offset_s - fit.offset_s == pytest.approx(-0.100, abs=0.015)
    assert moved.link == "gripper_link"


def test_the_camera_declared_on_the_other_arm_is_named(tmp_path_factory: pytest.TempPathFactory,
                                                       so101_urdf: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    spec = VideoDatasetSpec(so101_urdf, seed=13, duration_s=DURATION_S, bimanual=True, camera_arm="right_",
                            declared_arm="left_")
    truth = generate_video_dataset(tmp_path_factory.mktemp("bimanual") / "dataset", spec)
    evidence = episode_evidence(truth, so101_urdf)
    assert {link.link for link in evidence.links} >= {"left_gripper_link", "right_gripper_link"}
    finished: list[str] = []

    def finish(searched: Searched) -> Joint | None:
        finished.append(searched.trials.link.link)
        return finish_fit(searched)

    monkeypatch.setattr(fit_module, "finish_fit", finish)
    fit = fit_episode(evidence, truth)
    # The declared link is searched but, misfitting far more than the right one, not fitted further ...
    assert finished == ["right_gripper_link"]
    # ... and the fit is the one fitting every candidate through gives.
    monkeypatch.setattr(fit_module, "SEARCH_SCREEN", np.inf)
    unscreened = fit_episode(evidence, truth)
    assert finished[1:] == ["right_gripper_link", "left_gripper_link"]  # the best searched first
    assert (unscreened.link, unscreened.offset_s) == (fit.link, fit.offset_s)
    np.testing.assert_array_equal(unscreened.q_link_cam, fit.q_link_cam)
    assert fit.link == "right_gripper_link"
    assert fit.wrong_link
    assert fit.declared_link == "left_gripper_link"
    assert fit.mount_error is None
    assert any("moves with right_gripper_link, not with the declared left_gripper_link" in note for note in fit.notes)
    others = [f.residual_deg for f in fit.links if f.link.startswith("left_")]
    assert min(others) > 5 * fit.links[0].residual_deg


def test_the_gripper_pads_are_left_out(faulted: tuple[VideoDatasetTruth, EpisodeEvidence, EgoMotionFit]) -> None:
    truth, evidence, _fit = faulted
    mask = np.zeros((truth.spec.height, truth.spec.width), dtype=np.uint8)
    for pad in gripper_pads(truth.spec.width, truth.spec.height):
        cv2.fillPoly(mask, [np.asarray(pad.polygon, dtype=np.int32)], 255)
    # Inside the pads by more than a pixel or two (a track on the edge follows the scene beside it).
    mask = cv2.erode(mask, np.ones((5, 5), np.uint8))
    tracks = evidence.tracks
    kept = 0
    for ids, pixels in zip(tracks.ids, tracks.pixels, strict=True):
        moving = ~np.isin(ids, tracks.fixed)
        px = np.rint(pixels[moving]).astype(int)
        kept += int(moving.sum())
        assert not mask[px[:, 1], px[:, 0]].any()
    assert kept > 100 * len(tracks.ids)


def test_implied_focal_length_when_the_intrinsics_are_wrong(clean: tuple[VideoDatasetTruth, EpisodeEvidence,
                                                                         EgoMotionFit]) -> None:
    truth, evidence, _fit = clean
    fx, fy, cx, cy = truth.intrinsics
    assumed = Intrinsics(fx=1.25 * fx, fy=1.25 * fy, cx=cx, cy=cy, width=truth.spec.width,
                         height=truth.spec.height, distortion_model="none")
    fit = fit_episode(evidence, truth, intrinsics=assumed)
    assert 1.25 * fx * fit.focal_scale == pytest.approx(fx, rel=0.05)


def test_a_still_camera_says_its_motion_is_not_observable(clean: tuple[VideoDatasetTruth, EpisodeEvidence,
                                                                       EgoMotionFit]) -> None:
    truth, evidence, _fit = clean
    still = np.repeat(evidence.frames.row_images()[:1], 60, axis=0)
    tracks = track_features(still)
    stamps = evidence.stamps_ns[:60]
    fit = fit_camera_motion(
        lambda prior, **options: measure_egomotion(tracks, stamps, evidence.intrinsics, frame="front",
                                                   translation=prior, **options),
        evidence.links, camera="front", declared_link="gripper_link", declared_q_link_cam=truth.q_link_cam)
    assert fit.link == ""
    assert not fit.offset_observable
    assert not fit.mount_observable
    assert fit.notes[0].startswith("camera front: none of its frame pairs could be measured (its frames repeat")
