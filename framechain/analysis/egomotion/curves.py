"""Each measured camera's rotation rate over time, as the outputs draw it: from its images, and as forward
kinematics predicts it through the declared link, mount and time and through the fitted ones.

Computed once per run (:attr:`framechain.analysis.run.Run.rotation_rates`); the report's plot and the Rerun
series draw these numbers as they are. A time offset shows as a shift between the curves, a mount error as a
misfit of the components (the magnitude does not see the mount).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from framechain.analysis.egomotion.fit import rotation_rates
from framechain.analysis.egomotion.run import CameraMotion, CameraMotionEvidence
from framechain.arrays import FloatArray, IntArray

__all__ = ["RateSeries", "RotationRateCurves", "camera_rate_curves", "rotation_rate_curves"]

#: A frame pair spanning more than this many times the shortest spans (their 10th percentile) is not a pair of
#: neighbouring frames: the curves keep the neighbours only.
NEIGHBOUR_SPAN = 1.5


@dataclass(frozen=True)
class RateSeries:
    """A camera's rotation rate per frame pair (deg/s): components in its optical frame, and magnitude."""

    components_deg_s: FloatArray  # (M, 3)
    magnitude_deg_s: FloatArray  # (M,)

    @classmethod
    def of(cls, rates_rad_s: FloatArray) -> RateSeries:
        components: FloatArray = np.rad2deg(rates_rad_s)
        return cls(components, np.linalg.norm(components, axis=1))


@dataclass(frozen=True)
class RotationRateCurves:
    """One camera's rotation rate over its pairs of neighbouring frames, in time order.

    ``middle_ns``: the middle of each pair (integer stamps); ``measured`` from the images, ``declared``
    through ``declared_link`` with the declared mount and no offset, ``fitted`` through ``link`` with the
    fitted mount, shifted by ``offset_s`` (the measured focal length over the fitted one applied).
    """

    camera: str
    declared_link: str
    link: str
    offset_s: float
    middle_ns: IntArray  # (M,)
    measured: RateSeries
    declared: RateSeries
    fitted: RateSeries


def neighbour_pairs(stamp0_ns: IntArray, stamp1_ns: IntArray) -> IntArray:
    """The pairs of neighbouring frames (the shortest spans), in time order."""
    span = stamp1_ns - stamp0_ns
    keep = np.flatnonzero(span <= NEIGHBOUR_SPAN * np.percentile(span, 10))
    out: IntArray = keep[np.argsort(stamp0_ns[keep], kind="stable")]
    return out


def camera_rate_curves(motion: CameraMotion) -> RotationRateCurves | None:
    """A camera's curves (None: its motion was not fitted to a link, or nothing was measured)."""
    fit = motion.fit
    if fit is None or not fit.link or not len(motion.table):
        return None
    table = motion.table
    pairs = neighbour_pairs(table.stamp0_ns, table.stamp1_ns)
    declared = rotation_rates(table, motion.link_motion(motion.declared_link), motion.declared_q_link_cam, 0.0)
    fitted = rotation_rates(table, motion.link_motion(fit.link), fit.q_link_cam, fit.offset_s,
                            focal_scale=fit.focal_scale / motion.measured_focal)
    middle = (table.stamp0_ns[pairs] + (table.stamp1_ns[pairs] - table.stamp0_ns[pairs]) // 2).astype(np.int64)
    return RotationRateCurves(
        camera=motion.camera, declared_link=motion.declared_link, link=fit.link, offset_s=fit.offset_s,
        middle_ns=middle, measured=RateSeries.of(declared.measured[pairs]),
        declared=RateSeries.of(declared.predicted[pairs]), fitted=RateSeries.of(fitted.predicted[pairs]))


def rotation_rate_curves(evidence: CameraMotionEvidence | None) -> tuple[RotationRateCurves, ...]:
    """The curves of every camera whose motion was fitted to a link (none without camera motion evidence)."""
    if evidence is None:
        return ()
    return tuple(c for c in (camera_rate_curves(m) for m in evidence.cameras) if c is not None)
