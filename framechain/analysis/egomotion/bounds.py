"""What a camera's own motion can and cannot decide: its bounds, its undetermined fits, whether it is explained.

A fit of the camera's rotation rate against forward kinematics gives an offset, a mount and a focal
scale with their intervals (:mod:`framechain.analysis.egomotion`). Before any of them becomes a
finding, three questions are asked here, one per camera:

- **Is the motion explained?** The misfit left with every fitted correction applied is set beside
  the misfit as declared and beside the motion itself. A model that leaves more than
  :data:`UNEXPLAINED_DEG_S` of misfit, or more than :data:`UNEXPLAINED_SHARE` of the camera's
  rotation rate, does not explain this camera's motion (a wrong pairing of frames with rows,
  electronically stabilised video, motors mapped onto another robot): no fix is offered from it.
- **Is each estimate determined?** An offset at the edge of its search window, or whose resamples
  pile up at the edge of the search around it; a focal length outside what a lens can be (a field
  of view of :data:`FOV_RANGE_DEG` across the image width) or uncertain by a factor of two; a mount
  whose interval spans more than :data:`MOUNT_SPREAD_DEG`. An undetermined estimate is never a
  finding and never bounded: it is said to be undetermined, with why.
- **How large must a fault be to be found?** The smallest offset, mount rotation and focal length
  departure that would be a finding (a size threshold widened by the fit's own interval): the
  bound. A family whose own estimate exceeds its bound is a finding or undetermined, never
  "no fault above" its bound.

Calibrated on generated episodes (standard, and recorded as real recorders do: real-time stamps,
repeats, MPEG-4, a wide lens, cloth) and on real footage with a gyro (a gimballed and a stabilised
GoPro): see the tests under tests/analysis/egomotion.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from framechain.analysis.egomotion import EgoMotionFit
from framechain.analysis.egomotion.fit import focal_hidden
from framechain.analysis.egomotion.run import CameraMotion
from framechain.analysis.verdict.checks import Bound
from framechain.catalogue import Fault, HopName
from framechain.geometry.camera import FOV_RANGE_DEG, focal_of_fov, fov_of_focal

__all__ = [
    "FOCAL_CLEAR",
    "FOCAL_GUESSED",
    "MIN_ANGLE_DEG",
    "MIN_OFFSET_S",
    "Judgement",
    "focal_clear",
    "focal_limits",
    "judge",
    "motion_bounds",
]

#: A time offset smaller than this (s) is not worth a fix.
MIN_OFFSET_S = 0.005
#: A mount rotation whose interval does not clear this (deg) is not worth a fix: clean generated episodes recorded as
#: real recorders do (MPEG-4, a wide lens, cloth, repeats) leave up to 1.6 deg of systematic mount error, which
#: bootstrap intervals do not hold.
MIN_ANGLE_DEG = 2.5
#: A focal length off by more than this (ratio), with an interval narrower than it, is a finding.
FOCAL_CLEAR = 0.10
#: A guessed focal length (from a field of view, or a robot.yaml framechain made) is corrected by a smaller departure:
#: it claims no calibration, and the mount and position fitted with the implied one rest on it (the rotation measured
#: from images of a scene at finite depth comes out up to about 1% off on clean generated episodes).
FOCAL_GUESSED = 0.03
#: The misfit left with every correction applied above which the model does not explain the motion (deg/s).
UNEXPLAINED_DEG_S = 10.0
#: ... or above this share of the camera's rotation rate (the larger of measured and predicted).
UNEXPLAINED_SHARE = 0.5
#: A bound is the size threshold or this many half-widths of the fit's 95% interval, whichever is larger: the
#: interval holds the estimate's spread from resampling, not its systematic error, which injected faults on
#: generated episodes show to reach about a half-width (one scene, gripper pads in view: a clean episode read
#: as +5.6 ms, a 10 ms delay as 4.7 ms, 15 ms as 7.7 ms, half-widths of 5 ms; without the pads, +3 ms). At two
#: half-widths a fault twice its bound is found and a clean episode is not.
BOUND_HALF_WIDTHS = 2.0
#: A focal scale whose interval spans more than this factor is undetermined.
FOCAL_SPREAD = 2.0
#: A mount rotation whose interval spans more than this (deg) is undetermined.
MOUNT_SPREAD_DEG = 60.0

@dataclass(frozen=True)
class Judgement:
    """One camera's motion judged: explained or not (and why), and each family's undetermined estimate."""

    explained: bool
    why_unexplained: str
    misfit_declared_deg_s: float
    misfit_fitted_deg_s: float
    motion_deg_s: float
    #: Per fault family (latency, rotation_error, intrinsics): why its estimate is undetermined.
    undetermined: dict[str, str]

    def to_json(self) -> dict[str, Any]:
        return {"explained": self.explained, "why": self.why_unexplained,
                "misfit_deg_s": {"declared": _num(self.misfit_declared_deg_s),
                                 "fitted": _num(self.misfit_fitted_deg_s), "motion": _num(self.motion_deg_s)},
                "undetermined": dict(self.undetermined)}


def focal_limits(motion: CameraMotion) -> tuple[float, float]:
    """The focal scales (over the declared focal length) a lens can have: a field of view within
    :data:`FOV_RANGE_DEG` across the image width (NaN when the width or the focal length is unknown)."""
    if motion.width_px <= 0 or not np.isfinite(motion.focal_px) or motion.focal_px <= 0:
        return float("nan"), float("nan")
    wide, narrow = FOV_RANGE_DEG[1], FOV_RANGE_DEG[0]
    return (focal_of_fov(motion.width_px, wide) / motion.focal_px,
            focal_of_fov(motion.width_px, narrow) / motion.focal_px)


def judge(motion: CameraMotion, fit: EgoMotionFit, declared_deg_s: float, fitted_deg_s: float,
          motion_deg_s: float) -> Judgement:
    """The camera's motion judged from its misfits (as declared, with every correction fitted) and its rate."""
    why = ""
    if fitted_deg_s > UNEXPLAINED_DEG_S or fitted_deg_s > UNEXPLAINED_SHARE * motion_deg_s:
        why = (f"the model does not explain the motion of camera {motion.camera}: with every correction fitted "
               f"{fitted_deg_s:.1f} deg/s of misfit is left ({declared_deg_s:.1f} as declared), against a rotation "
               f"rate of {motion_deg_s:.1f} deg/s")
    return Judgement(explained=not why, why_unexplained=why, misfit_declared_deg_s=declared_deg_s,
                     misfit_fitted_deg_s=fitted_deg_s, motion_deg_s=motion_deg_s,
                     undetermined=_undetermined(motion, fit))


def _undetermined(motion: CameraMotion, fit: EgoMotionFit) -> dict[str, str]:
    out: dict[str, str] = {}
    if fit.offset_undetermined:
        out[Fault.LATENCY.value] = f"its time offset is undetermined: {fit.offset_undetermined}"
    low, high = fit.focal_scale_interval
    lens_low, lens_high = focal_limits(motion)
    scale = fit.focal_scale
    if not np.isfinite(scale):
        out[Fault.INTRINSICS.value] = "the focal length its motion implies could not be measured"
    elif np.isfinite(lens_low) and not lens_low <= scale <= lens_high:
        fov = fov_of_focal(motion.width_px, scale * motion.focal_px)
        out[Fault.INTRINSICS.value] = (f"the focal length its motion implies ({scale:.3f} times the declared one, a "
                                       f"{fov:.0f} deg field of view) is no lens's: undetermined")
    elif low > 0 and high / low > FOCAL_SPREAD:
        out[Fault.INTRINSICS.value] = (f"the focal length its motion implies is undetermined ({low:.3f} .. "
                                       f"{high:.3f} times the declared one)")
    elif (swung := focal_hidden(fit)) is not None:
        out[Fault.INTRINSICS.value] = (
            f"its images cannot tell its rotation across the optical axis from its translation (in {swung:.0%} of "
            "its frame pairs the translation moves the image the way the rotation does, as when a camera turns about "
            "one axis at a distance from it): the focal length its motion implies is undetermined")
    error = fit.mount_error
    if motion.guessed and motion.position is None and fit.mount_unobservable_axes and error is not None:
        axis = ", ".join(f"{v:.2f}" for v in fit.mount_unobservable_axes[0])
        out[Fault.ROTATION_ERROR.value] = (
            f"its mount about [{axis}] of {fit.link} is not observable here, and the mount it would be kept at is a "
            "guess (robot.yaml was made by framechain): its mount rotation is undetermined")
    elif error is not None and error.interval_deg[1] - error.interval_deg[0] > MOUNT_SPREAD_DEG:
        out[Fault.ROTATION_ERROR.value] = (f"its mount rotation is undetermined ({error.interval_deg[0]:.0f} .. "
                                           f"{error.interval_deg[1]:.0f} deg)")
    return out


def motion_bounds(motion: CameraMotion, judgement: Judgement | None = None) -> tuple[Bound, ...]:
    """What the camera's motion can show of each sized family, as attribution bounds (camera named): the
    smallest offset, mount rotation and focal length departure the rate fit would make a finding of (the
    size thresholds widened by the fit's own interval), or why it cannot see them (not observable,
    undetermined, a motion the model does not explain)."""
    fit = motion.fit
    hop, camera = HopName.CAMERA_TO_BODY, motion.camera
    families = ((hop, Fault.LATENCY), (hop, Fault.ROTATION_ERROR), (HopName.PIXEL_TO_CAMERA, Fault.INTRINSICS))
    if fit is None or not fit.link:
        return tuple(Bound(h, f, False, None, motion.why_not, camera=camera) for h, f in families)
    if judgement is not None and not judgement.explained:
        return tuple(Bound(h, f, False, None, f"undetermined: {judgement.why_unexplained}", camera=camera)
                     for h, f in families)
    undetermined = judgement.undetermined if judgement is not None else {}
    out = []
    for (h, fault), bound in zip(families, (_latency_bound(motion, fit), _mount_bound(motion, fit),
                                            _focal_bound(motion, fit)), strict=True):
        why = undetermined.get(fault.value)
        out.append(Bound(h, fault, False, None, f"undetermined: {why}", camera=camera) if why else bound)
    return tuple(out)


def _latency_bound(motion: CameraMotion, fit: EgoMotionFit) -> Bound:
    """A latency finding needs an interval clear of 0 and an offset of at least the bound (MIN_OFFSET_S, or
    :data:`BOUND_HALF_WIDTHS` half-widths of the interval when that is larger)."""
    hop, camera = HopName.CAMERA_TO_BODY, motion.camera
    if fit.unobservable:
        return Bound(hop, Fault.LATENCY, False, None, f"camera {camera}: {fit.unobservable}", camera=camera)
    if not fit.offset_observable:
        return Bound(hop, Fault.LATENCY, False, None, f"undetermined: {fit.offset_undetermined}", camera=camera)
    low, high = fit.offset_interval_s
    if low <= 0.0 <= high and abs(fit.offset_s) > latency_bound_s(fit):
        return Bound(hop, Fault.LATENCY, False, None, f"undetermined: its time offset ({fit.offset_s * 1e3:+.1f} ms) "
                     "is "
                     f"larger than the fit could bound, yet its interval ({low * 1e3:+.1f} .. {high * 1e3:+.1f} ms) "
                     "holds zero", camera=camera)
    return Bound(hop, Fault.LATENCY, True, {"offset_s": _num(latency_bound_s(fit)) or 0.0}, "", camera=camera)


def latency_bound_s(fit: EgoMotionFit) -> float:
    """The smallest offset the fit would make a finding of (s)."""
    return offset_bound_s(fit.offset_interval_s)


def offset_bound_s(interval_s: tuple[float, float]) -> float:
    """The smallest offset a fit with this 95% interval would make a finding of (s): MIN_OFFSET_S, or
    :data:`BOUND_HALF_WIDTHS` half-widths of the interval when that is larger."""
    low, high = interval_s
    return max(MIN_OFFSET_S, BOUND_HALF_WIDTHS * (0.5 * (high - low)))


def mount_bound_deg(fit: EgoMotionFit) -> float:
    """The smallest mount rotation the fit would make a finding of (deg)."""
    assert fit.mount_error is not None
    spread = fit.mount_error.interval_deg
    return angle_bound_deg(0.5 * (spread[1] - spread[0]))


def angle_bound_deg(half_width_deg: float) -> float:
    """The smallest mount rotation a fit with this half-width of interval would make a finding of (deg):
    MIN_ANGLE_DEG beyond :data:`BOUND_HALF_WIDTHS` half-widths."""
    return MIN_ANGLE_DEG + BOUND_HALF_WIDTHS * half_width_deg


def _mount_bound(motion: CameraMotion, fit: EgoMotionFit) -> Bound:
    hop, camera = HopName.CAMERA_TO_BODY, motion.camera
    if fit.mount_error is None:
        return Bound(hop, Fault.ROTATION_ERROR, False, None, f"camera {camera} moves with {fit.link}, not the declared "
                     f"{motion.declared_link}: its mount there is not measured", camera=camera)
    if not fit.mount_observable:
        return Bound(hop, Fault.ROTATION_ERROR, False, None, f"camera {camera}: {fit.unobservable}", camera=camera)
    return Bound(hop, Fault.ROTATION_ERROR, True, {"angle_deg": _num(mount_bound_deg(fit)) or 0.0}, "",
                 unobservable_axes=fit.mount_unobservable_axes, camera=camera)


def focal_clear(motion: CameraMotion) -> float:
    """The departure of the focal length (ratio) that is a finding: :data:`FOCAL_CLEAR` for declared intrinsics,
    :data:`FOCAL_GUESSED` for guessed ones."""
    return FOCAL_CLEAR if motion.intrinsics_known else FOCAL_GUESSED


def _focal_bound(motion: CameraMotion, fit: EgoMotionFit) -> Bound:
    """An intrinsics finding needs a departure over :func:`focal_clear` measured within an interval narrower than
    FOCAL_CLEAR."""
    low, high = fit.focal_scale_interval
    hop, camera = HopName.PIXEL_TO_CAMERA, motion.camera
    if fit.unobservable:
        return Bound(hop, Fault.INTRINSICS, False, None, f"camera {camera}: {fit.unobservable}", camera=camera)
    if not np.isfinite(fit.focal_scale) or not high - low < FOCAL_CLEAR:
        return Bound(hop, Fault.INTRINSICS, False, None, f"camera {camera}: the focal length its motion implies is "
                     f"uncertain by more than {FOCAL_CLEAR:.0%}", camera=camera)
    return Bound(hop, Fault.INTRINSICS, True, {"scale": focal_clear(motion)}, "", camera=camera)


#: A rotation rate has no depth in it: the cameras' own motion cannot scale their depth.
NO_DEPTH = Bound(HopName.PIXEL_TO_CAMERA, Fault.DEPTH_SCALE, False, None,
                 "a camera's rotation carries no depth: no depth scale is measured from the cameras' own motion")


def observability(motion: CameraMotion, judgement: Judgement | None) -> list[dict[str, Any]]:
    """The camera's bounds, and whether the link it moves with is told apart from the others."""
    fit = motion.fit
    out = [b.to_json() for b in motion_bounds(motion, judgement)]
    ambiguous = fit is not None and bool(fit.alternatives)
    why = motion.why_not if fit is None or not fit.link else (
        f"camera {motion.camera}: {fit.unobservable}" if fit.unobservable else
        f"{', '.join(fit.alternatives)} move(s) as {fit.link} does" if ambiguous else "")
    seen = fit is not None and bool(fit.link) and not fit.unobservable and not ambiguous
    out.append({"hop": HopName.CAMERA_TO_BODY.value, "fault": Fault.WRONG_CAMERA_FRAME.value, "camera": motion.camera,
                "observable": seen, "min_detectable": None, "why": why})
    return out


def _num(value: float) -> float | None:
    return round(float(value), 6) if np.isfinite(value) else None
