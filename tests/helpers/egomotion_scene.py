"""Camera-motion evidence of a generated LeRobot episode, from the dataset on disk to the fit.

The steps the pipeline will take (phase 2 wires them into the Run): read the episode's rows with
framechain's dataset reader, decode the wrist video's frame of each row, track features, compute
the candidate links' rotations with framechain's kinematics from the stored state, and fit. The
truth the tests compare against comes from the generator's own maths
(:mod:`framechain.sim.lerobot_video`), never from these steps.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain.adapters.lerobot.reader import DatasetReader
from framechain.adapters.lerobot.video import (
    VideoFrames,
    VideoHealth,
    episode_frame_times_ns,
    read_frames,
    video_health,
)
from framechain.analysis.egomotion import (
    EgoMotionFit,
    EgoMotionFitOptions,
    LinkMotion,
    fit_camera_motion,
)
from framechain.arrays import IntArray
from framechain.config.calibration import Intrinsics
from framechain.robot.kinematics import RobotModel
from framechain.sim.lerobot_video import (
    ARM_JOINTS,
    VideoDatasetSpec,
    VideoDatasetTruth,
    generate_video_dataset,
    write_robot_yaml,
)
from framechain.timeline import EgoMotionTable, TranslationPrior
from framechain.vision.egomotion import EgoMotionOptions, FeatureTracks, measure_egomotion, track_features

#: The links every test offers as candidates (per arm).
CANDIDATE_LINKS = ("gripper_link", "wrist_link", "lower_arm_link")


@dataclass(frozen=True)
class EpisodeEvidence:
    """One episode's decoded frames, their health, feature tracks, declared intrinsics and candidate links."""

    frames: VideoFrames
    health: VideoHealth
    stamps_ns: IntArray
    tracks: FeatureTracks
    intrinsics: Intrinsics
    links: tuple[LinkMotion, ...]


def generated(factory: pytest.TempPathFactory, name: str, spec: VideoDatasetSpec) -> tuple[VideoDatasetTruth, Path]:
    """A dataset generated in a folder of its own under ``factory``, and its robot.yaml beside it."""
    folder = factory.mktemp(name)
    truth = generate_video_dataset(folder / "dataset", spec)
    return truth, write_robot_yaml(truth, folder / "robot.yaml")


def episode_evidence(
    truth: VideoDatasetTruth, urdf: Path, episode: int = 0, *, root: Path | None = None,
    links: Sequence[str] = CANDIDATE_LINKS, options: EgoMotionOptions | None = None,
) -> EpisodeEvidence:
    """Everything the fit needs from the dataset at ``root`` (default: the generated one)."""
    reader = DatasetReader(root or truth.root)
    info = reader.episode(episode)
    rows = reader.read(episode, ["observation.state"])
    key = truth.video_key
    times = episode_frame_times_ns(rows.timestamp_s, info.video_from_s.get(key, 0.0))
    # A frame sent twice may come back from H.264 a fraction of a grey level off; a moving wrist
    # camera's frames differ by tens of levels.
    frames = read_frames(info.video_files[key], times, repeat_level=1.0)
    tracks = track_features(frames.row_images(), usable=frames.usable, options=options)
    fx, fy, cx, cy = truth.intrinsics
    scale = truth.declared_focal_px / fx
    intrinsics = Intrinsics(fx=fx * scale, fy=fy * scale, cx=cx, cy=cy, width=truth.spec.width,
                            height=truth.spec.height, distortion_model="none")
    model = RobotModel.from_urdf(urdf)
    state = np.asarray(rows.columns["observation.state"], dtype=np.float64)
    stamps = rows.stamp_ns
    candidates = []
    for arm in truth.arms:
        columns = [truth.state_names.index(f"{arm}{joint}.pos") for joint in ARM_JOINTS]
        q = {joint: np.deg2rad(state[:, c]) for joint, c in zip(ARM_JOINTS, columns, strict=True)}
        for name, pose in model.link_poses(q, links=list(links), default=0.0).items():
            candidates.append(LinkMotion(arm + name, stamps, Rotation.from_matrix(pose[:, :3, :3]).as_quat(),
                                         pose[:, :3, 3].copy()))
    return EpisodeEvidence(frames=frames, health=video_health(frames, rows.frame_index, key), stamps_ns=stamps,
                           tracks=tracks, intrinsics=intrinsics, links=tuple(candidates))


def fit_episode(
    evidence: EpisodeEvidence, truth: VideoDatasetTruth, *, options: EgoMotionOptions | None = None,
    fit_options: EgoMotionFitOptions | None = None, intrinsics: Intrinsics | None = None,
) -> EgoMotionFit:
    """The camera-motion fit of one episode against its candidate links, with the declared mount."""

    def measure(prior: TranslationPrior | None, /, *, rotations_only: bool = False) -> EgoMotionTable:
        return measure_egomotion(evidence.tracks, evidence.stamps_ns, intrinsics or evidence.intrinsics,
                                 frame="wrist_optical_frame", translation=prior, options=options,
                                 rotations_only=rotations_only)

    return fit_camera_motion(measure, evidence.links, camera="wrist", declared_link=truth.declared_link,
                             declared_q_link_cam=truth.declared_q_link_cam,
                             declared_xyz_link_cam=truth.xyz_link_cam, options=fit_options)


def shifted_copy(root: Path, destination: Path, shift_s: float) -> Path:
    """A copy of the dataset whose videos' timestamps are all ``shift_s`` later (packets re-muxed, not re-encoded)."""
    import av

    shutil.copytree(root, destination)
    for video in sorted((destination / "videos").rglob("*.mp4")):
        source = video.with_suffix(".orig.mp4")
        video.rename(source)
        with av.open(str(source)) as inp, av.open(str(video), "w") as out:
            stream_in = inp.streams.video[0]
            stream_out = out.add_stream_from_template(stream_in)
            shift = round(Fraction(shift_s).limit_denominator(1_000_000) / stream_in.time_base)
            for packet in inp.demux(stream_in):
                if packet.dts is None:
                    continue
                packet.pts += shift
                packet.dts += shift
                packet.stream = stream_out
                out.mux(packet)
        source.unlink()
    return destination
