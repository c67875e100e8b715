"""Apply the fixes of an attribution to a timeline, so the corrected log can be replayed again.

Only faults found in the recorded data (against a reference or by a static target's spread) are
corrected here: a camera mount's rotation, detection stamps that run late, a depth scale, the
intrinsics. Faults in the robot's computation are fixed in the robot's code, not in its log.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from framechain.analysis.model.estimates import LatencyEstimate, RotationEstimate, ScaleEstimate
from framechain.analysis.verdict.attribute import Attribution
from framechain.analysis.verdict.fixes import corrected_mount
from framechain.arrays import FloatArray
from framechain.geometry.rotations import quat_from_rpy
from framechain.timeline import DepthFrameTable, Timeline, TransformTable


class NothingToCorrectError(ValueError):
    """The attribution has no finding in the recorded data."""


def apply_corrections(timeline: Timeline, result: Attribution) -> Timeline:
    """The timeline with every recorded-data finding of ``result`` corrected."""
    if result.metric not in ("reference", "static_spread"):
        raise NothingToCorrectError(
            f"findings against {result.metric.replace('_', ' ')} describe the robot's computation; "
            "fix the robot, not the log"
        )
    out = timeline
    for finding in result.findings:
        e = finding.estimate
        if isinstance(e, RotationEstimate):
            # The estimate is the faulty (recorded) mount relative to the right one: undo it.
            rotvec = -np.deg2rad(e.angle_deg) * np.asarray(e.axis, dtype=float)
            mount = corrected_mount(result.inputs, rotvec, "correction")
            if mount is None:
                raise NothingToCorrectError("the camera hangs from no static mount edge to correct")
            parent, child, xyz, rpy = mount
            out = _replace_static_edge(out, parent, child, xyz, quat_from_rpy(rpy))
        elif isinstance(e, LatencyEstimate):
            # The pose at tau + offset explains the detection: the camera's clock is off by the offset,
            # so everything it stamped moves (detections, depth frames, CameraInfo of that camera).
            shift = round(e.offset_s * 1e9)
            camera = result.config.frames.camera
            obs = out.observations
            depth = out.depth_frames
            cams = out.cameras
            out = out.replace(
                observations=dataclasses.replace(obs, stamp_ns=obs.stamp_ns + shift),
                depth_frames=dataclasses.replace(
                    depth, stamp_ns=np.where(depth.frame == camera, depth.stamp_ns + shift, depth.stamp_ns)
                ),
                cameras=dataclasses.replace(cams, stamp_ns=np.where(cams.frame == camera, cams.stamp_ns + shift,
                                                                    cams.stamp_ns)),
            )
        elif isinstance(e, ScaleEstimate) and e.name == "factor":
            factor = e.value
            obs = out.observations
            out = out.replace(observations=dataclasses.replace(obs, depth_m=obs.depth_m / factor))
            out = out.replace(depth_frames=_scaled_depth(out.depth_frames, 1.0 / factor))
        elif isinstance(e, ScaleEstimate):
            scale = e.value
            cams = out.cameras
            k = cams.K.copy()
            k[:, 0, 0] /= scale
            k[:, 1, 1] /= scale
            if e.variant == "resolution":
                k[:, :2, 2] /= scale
            out = out.replace(cameras=dataclasses.replace(cams, K=k))
    return out


def _replace_static_edge(
    timeline: Timeline, parent: str, child: str, xyz: FloatArray, quat_xyzw: FloatArray
) -> Timeline:
    tf = timeline.transforms
    keep = ~((tf.child == child) & tf.is_static)
    stamp = int(tf.stamp_ns[~keep][0]) if (~keep).any() else 0
    corrected = TransformTable.from_rows(parent, child, [stamp], [xyz], [quat_xyzw], is_static=True,
                                         source="framechain/corrected")
    return timeline.replace(transforms=TransformTable.concat([tf.take(keep), corrected]))


def _scaled_depth(frames: DepthFrameTable, factor: float) -> DepthFrameTable:
    base = frames.loader
    if base is None or len(frames) == 0:
        return frames
    return dataclasses.replace(frames, loader=lambda i: (base(i) * np.float32(factor)).astype(np.float32))
