"""The camera-motion fit on real footage: two GoPro clips, their images against their own gyro.

The gyro (read from the clip's GPMF telemetry by :mod:`tests.helpers.gpmf`, integrated by
:mod:`tests.helpers.gopro_clip`) plays the part forward kinematics plays for a camera on a robot link;
nothing in framechain knows it is a gyro, except that a gyro has a rate bias the fit is asked to carry.
The truths are independent of framechain: gpmf-parser's documentation of the Hero5's axes
(:func:`tests.helpers.gopro_clip.documented_mount`), and what the clips are.

- karma.mp4: a camera on a drone's gimbal, still for most of the clip, then one pan at its end.
  The whole clip gives an offset with a narrow interval and a mount that agrees with the documented
  axes; its first half, where the gimbal holds the camera still, shows nothing.
- max-heromode.mp4: hand-held and electronically stabilised: its images do not turn as its body
  does, and the model does not explain them.

The window of the offset search is 0.1 s: the gyro and the video are written by one device on one
clock (GPMF packets are stamped within 0.1 s of the frames they ride with).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain.analysis.egomotion import EgoMotionFitOptions, fit_camera_motion
from framechain.analysis.egomotion.findings import MotionFindings, motion_findings
from framechain.analysis.egomotion.run import CameraMotion, CameraMotionEvidence
from framechain.analysis.verdict.findings import motion_verdict
from framechain.timeline import EgoMotionTable
from tests.helpers.gopro_clip import (
    clip_motion,
    clip_tracks,
    decode_clip,
    documented_mount,
    gopro_intrinsics,
    gyro_link,
)
from tests.helpers.gpmf import read_stream
from tests.helpers.realdata import gopro_clip

#: karma.mp4 pans right at up to 45 deg/s from about 11.4 s; its gimbal holds the camera still before.
STILL_UNTIL_S = 6.04
OPTIONS = EgoMotionFitOptions(max_offset_s=0.1, rate_bias=True)


def _measured(path: Path) -> tuple[EgoMotionTable, Any]:
    frames = decode_clip(path)
    # An equidistant fisheye of 550 px per radian: what karma's pan shows at the centre and both sides alike.
    intrinsics = gopro_intrinsics(frames.images.shape[2], frames.images.shape[1], lens="equidistant", hfov_deg=89.0)
    return clip_motion(clip_tracks(frames), frames, intrinsics), intrinsics


@pytest.fixture(scope="module")
def karma(realdata: Path) -> tuple[Path, EgoMotionTable, Any]:
    path = gopro_clip(realdata, "karma.mp4")
    return (path, *_measured(path))


@pytest.fixture(scope="module")
def max_clip(realdata: Path) -> tuple[Path, EgoMotionTable, Any]:
    path = gopro_clip(realdata, "max-heromode.mp4")
    return (path, *_measured(path))


def judged(clip: tuple[Path, EgoMotionTable, Any], *, until_s: float = np.inf,
           declared: np.ndarray | None = None) -> tuple[CameraMotion, MotionFindings]:
    """The clip's images against its gyro, through the fit and the judgement a run's cameras get."""
    path, table, intrinsics = clip
    gyro = read_stream(path, "GYRO")
    link = gyro_link(gyro)
    part = table.take(np.flatnonzero(table.stamp1_ns * 1e-9 <= until_s))
    mount = documented_mount(gyro.axis_order) if declared is None else declared
    q = Rotation.from_matrix(mount).as_quat()
    # No translation prior: the gyro's link has no positions, so every measurement is this rotation-only one.
    fit = fit_camera_motion(lambda _prior, **_options: part, [link], camera="gopro", declared_link=link.link,
                            declared_q_link_cam=q, options=OPTIONS)
    motion = CameraMotion(camera="gopro", declared_link=link.link, declared_q_link_cam=q,
                          declared_xyz_link_cam=np.zeros(3), fit=fit, table=part, links=(link,),
                          focal_px=intrinsics.fx, width_px=intrinsics.width)
    return motion, motion_findings(CameraMotionEvidence((motion,)), {})


def verdict(found: MotionFindings) -> str:
    """The verdict sentence attribute prints over these findings."""
    rates = found.residual_before[np.isfinite(found.residual_before)]
    return motion_verdict(found.findings, found.bounds, found.entries, float(np.median(rates)) if rates.size else None)


def test_karma_whole_clip_gives_an_offset_with_a_narrow_interval(karma: tuple[Path, EgoMotionTable, Any]) -> None:
    _motion, found = judged(karma)
    (entry,) = found.entries
    low, high = entry["offset_interval_s"]
    assert entry["explained"]
    assert high - low < 0.010
    # Phase correlation of the image centre against the gyro reads the images 12 ms behind it
    # (tests/analysis/egomotion/test_gpmf_reader.py): the fitted offset agrees to a few milliseconds.
    assert entry["offset_s"] == pytest.approx(-0.012, abs=0.005)
    assert low < entry["offset_s"] < high
    (latency,) = [f for f in found.findings if f.fault.value == "latency"]
    assert latency.camera == "gopro"


def test_karma_gyro_to_camera_rotation_is_the_documented_axis_permutation(
        karma: tuple[Path, EgoMotionTable, Any]) -> None:
    """The pan turns the camera about one axis, so the mount about it is kept as declared; about the two other
    axes it is measured, and it lands within 3 deg of the signed axis permutation gpmf-parser documents (the gyro
    sits on the camera's board, aligned to a degree or so)."""
    path = karma[0]
    documented = documented_mount(read_stream(path, "GYRO").axis_order)
    motion, _found = judged(karma)
    assert motion.fit is not None
    fitted = Rotation.from_quat(motion.fit.q_link_cam).as_matrix()
    assert np.rad2deg(Rotation.from_matrix(documented.T @ fitted).magnitude()) < 3.0  # 0.97 deg measured
    # Declared as no rotation at all, the measured part alone still sends the pan's axis where the documented
    # permutation sends it.
    motion, _found = judged(karma, declared=np.eye(3))
    assert motion.fit is not None
    (axis,) = motion.fit.mount_unobservable_axes
    fitted = Rotation.from_quat(motion.fit.q_link_cam).as_matrix()
    cosine = float(np.clip((fitted.T @ np.asarray(axis)) @ (documented.T @ np.asarray(axis)), -1.0, 1.0))
    assert np.rad2deg(np.arccos(cosine)) < 3.0  # 0.97 deg measured


def test_karma_still_first_half_is_not_observable(karma: tuple[Path, EgoMotionTable, Any]) -> None:
    motion, found = judged(karma, until_s=STILL_UNTIL_S)
    assert motion.fit is not None
    assert not found.findings
    assert not motion.fit.offset_observable
    latency = next(b for b in found.bounds if b.fault.value == "latency")
    assert not latency.observable
    assert "turns" in latency.why
    assert verdict(found).startswith("Nothing could be checked")


def test_a_stabilised_clip_is_not_explained_and_claims_no_offset(max_clip: tuple[Path, EgoMotionTable, Any]) -> None:
    _motion, found = judged(max_clip)
    (entry,) = found.entries
    assert entry["explained"] is False
    assert not found.findings
    text = verdict(found)
    assert text.startswith("Inconclusive: the model does not explain the motion of camera gopro")
    assert "no fix is offered" in text
    assert "ms camera latency" not in text  # no bound, no offset
