"""The faults of one camera of a rig, fitted against the other cameras: its mount's rotation and position,
its stamps' offset, its focal length and its depth scale; each names the camera, and its fix says which
camera to recalibrate with the corrected value in the chain's own form.

Every model is a :class:`~framechain.analysis.model.fault.FaultModel` over the rig's
:class:`~framechain.analysis.model.chain.CameraDelta`, fitted in ``correction`` mode (the parameters
correct the recorded data): the estimate is the fault, the inverse of the correction. Which cameras get
models is the layout's call (:meth:`~framechain.analysis.evidence.rig_layout.RigLayout.checkable`): a gauge camera
of a pair is held, the other carries what is found between them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from framechain.analysis.evidence.cross_camera import frame_periods_ns
from framechain.analysis.evidence.rig_layout import RigLayout, RigPose
from framechain.analysis.model.chain import ChainInputs
from framechain.analysis.model.estimates import LatencyEstimate, RotationEstimate, ScaleEstimate, TranslationEstimate
from framechain.analysis.model.fault import FaultModel, Mode
from framechain.analysis.model.faults import LATENCY_BOUND_S, SAME_ROTATION_DEG
from framechain.arrays import FloatArray
from framechain.catalogue import Fault, HopName
from framechain.config.mount import Mount
from framechain.geometry.rotations import (
    quat_angle,
    quat_from_rotvec,
    quat_multiply,
    quat_rotate,
    quat_to_rotvec,
    quat_to_rpy,
)

#: A camera's mount position may be off by at most this much (m) in a fit.
TRANSLATION_BOUND_M = 1.0
#: A camera's focal length or depths may be off by at most these factors in a fit.
SCALE_BOUNDS = (0.5, 2.0)
#: Faults of one rig camera within these are within what cross-checking per-tag detections can pin on the
#: camera, so they are no finding (the rig's notes give the disagreement left): a principal point or lens model a
#: few pixels off turns a camera's view by about a degree (15 px at a 470 px focal length is 1.8 deg) and is
#: indistinguishable from its mount turned; per-tag PnP places a tag a few centimetres off, which between two
#: cameras looks like their baseline (or the tags' size) off by as much; cameras exposed a fraction of a frame
#: apart disagree by that fraction of the motion. On tagslam_quad_rig as recorded the pairs disagree by up to
#: 1.4 deg and 4 cm; the faults worth a recalibration are degrees and frames.
ROTATION_TOLERANCE_DEG = 2.0
TRANSLATION_TOLERANCE_M = 0.05
SCALE_TOLERANCE = 0.05
LATENCY_TOLERANCE_FRAMES = 0.5


def rig_models(inputs: ChainInputs, layout: RigLayout, mounts: Mapping[str, Mount],
               camera_sources: Mapping[int, str]) -> list[FaultModel]:
    """Every per-camera fault the rig's evidence can show.

    ``mounts`` are the chain's mount entries by child frame (a fix writes them back in their form);
    ``camera_sources`` where each camera's model came from (a calibration file, a CameraInfo topic).
    """
    out: list[FaultModel] = []
    periods_s = frame_periods_ns(inputs) * 1e-9
    for k, cam in enumerate(inputs.rig_cameras):
        if not layout.checkable(k):
            continue
        note = layout.gauge_note(k)
        out += [
            _rotation(k, cam.frame, mounts, note),
            _translation(k, cam.frame, mounts, note),
            _focal(k, cam.frame, camera_sources.get(k, ""), note),
            _depth(k, cam.frame, note),
        ]
        if layout.pose is RigPose.MOVING or layout.compared[k] > 0:
            out.append(_latency(k, cam.frame, note, layout.pose, float(periods_s[k])))
    return out


def _within_scale(x: FloatArray) -> bool:
    return abs(float(x[0]) - 1.0) <= SCALE_TOLERANCE


def _model(k: int, frame: str, what: str, fault: Fault, hop: HopName, **kwargs: object) -> FaultModel:
    return FaultModel(name=f"{what}[{frame}]", fault=fault, hop=hop, family=f"camera:{frame}:{what}", camera=frame,
                      **kwargs)  # type: ignore[arg-type]


def _rotation(k: int, frame: str, mounts: Mapping[str, Mount], note: str) -> FaultModel:
    def estimate(x: FloatArray, mode: Mode, inputs: ChainInputs) -> RotationEstimate:
        rotvec = -np.asarray(x, dtype=float)  # the faulty mount relative to the right one
        angle = float(np.linalg.norm(rotvec))
        axis = rotvec / angle if angle > 0 else np.array([0.0, 0.0, 1.0])
        mount = inputs.rig_cameras[k].mount
        ax, ay, az = (round(float(a), 4) + 0.0 for a in axis)
        return RotationEstimate(angle_deg=round(float(np.rad2deg(angle)), 4), axis=(ax, ay, az),
                                axis_frame=mount.link if mount is not None else frame, faulty="recorded data")

    def fix(x: FloatArray, mode: Mode, inputs: ChainInputs) -> str:
        mount = inputs.rig_cameras[k].mount
        angle = float(np.rad2deg(np.linalg.norm(x)))
        if mount is None:
            return f"Recalibrate camera {frame}: turn its mount by {angle:.2f} deg (no static mount to correct){note}."
        right = quat_multiply(mount.q_parent_link, quat_from_rotvec(np.asarray(x, dtype=float)))
        lost = " has no rotation" if np.rad2deg(quat_angle(mount.q_parent_link)) < SAME_ROTATION_DEG else ""
        written = _mount_text(mount.parent, mount.link, mount.t_parent_link, right, mounts)
        return (f"Recalibrate camera {frame}: its recorded mount {mount.parent} -> {mount.link}{lost} is off by "
                f"{angle:.2f} deg; the corrected mount: {written}{note}")

    return _model(k, frame, "mount_rotation", Fault.ROTATION_ERROR, HopName.CAMERA_TO_BODY, x0=(0.0, 0.0, 0.0),
                  lower=(-np.pi,) * 3, upper=(np.pi,) * 3, plausibility_bounds=False, x_scale=(0.05,) * 3,
                  apply=lambda p, x: p.with_camera(k, rotvec_mount=np.asarray(x, dtype=float)), estimate=estimate,
                  fix=fix, tolerance=lambda x: float(np.rad2deg(np.linalg.norm(x))) <= ROTATION_TOLERANCE_DEG)


def _translation(k: int, frame: str, mounts: Mapping[str, Mount], note: str) -> FaultModel:
    def estimate(x: FloatArray, mode: Mode, inputs: ChainInputs) -> TranslationEstimate:
        ox, oy, oz = (round(-float(v), 6) + 0.0 for v in x)
        return TranslationEstimate(offset_m=(ox, oy, oz), frame=inputs.frames.body, faulty="recorded data")

    def fix(x: FloatArray, mode: Mode, inputs: ChainInputs) -> str:
        mount = inputs.rig_cameras[k].mount
        moved = float(np.linalg.norm(x)) * 1e3
        if mount is None:
            return f"Recalibrate camera {frame}: move it by {moved:.1f} mm in {inputs.frames.body}{note}."
        # The correction is in the body's axes; the mount's translation is in its parent's.
        parent_from_body = _parent_from_body(inputs, mount.parent)
        right = np.asarray(mount.t_parent_link) + quat_rotate(parent_from_body, np.asarray(x, dtype=float))
        written = _mount_text(mount.parent, mount.link, right, mount.q_parent_link, mounts)
        return (f"Recalibrate camera {frame}: its recorded mount {mount.parent} -> {mount.link} is {moved:.1f} mm off "
                f"in position; the corrected mount: {written}{note}")

    bound = TRANSLATION_BOUND_M
    return _model(k, frame, "mount_translation", Fault.TRANSLATION_ERROR, HopName.CAMERA_TO_BODY,
                  x0=(0.0, 0.0, 0.0), lower=(-bound,) * 3, upper=(bound,) * 3, x_scale=(0.01,) * 3,
                  apply=lambda p, x: p.with_camera(k, translation_m=np.asarray(x, dtype=float)), estimate=estimate,
                  fix=fix, tolerance=lambda x: float(np.linalg.norm(x)) <= TRANSLATION_TOLERANCE_M)


def _latency(k: int, frame: str, note: str, pose: RigPose, period_s: float) -> FaultModel:
    against = "the rig's pose" if pose is RigPose.MOVING else "the other cameras"

    def fix(x: FloatArray, mode: Mode, inputs: ChainInputs) -> str:
        ms = float(x[0]) * 1e3
        side = "late" if ms < 0 else "early"
        return (f"Camera {frame}'s detections are stamped {abs(ms):.1f} ms {side} against {against}: correct its "
                f"clock or its stamping offset (its true capture time is header.stamp {ms:+.1f} ms){note}.")

    return _model(k, frame, "stamp_offset", Fault.LATENCY, HopName.BODY_TO_WORLD, x0=(0.0,),
                  lower=(-LATENCY_BOUND_S,), upper=(LATENCY_BOUND_S,), x_scale=(0.01,),
                  apply=lambda p, x: p.with_camera(k, offset_s=float(x[0])),
                  estimate=lambda x, mode, inputs: LatencyEstimate(offset_s=round(float(x[0]), 6)), fix=fix,
                  tolerance=lambda x: abs(float(x[0])) <= LATENCY_TOLERANCE_FRAMES * period_s)


def _focal(k: int, frame: str, source: str, note: str) -> FaultModel:
    def fix(x: FloatArray, mode: Mode, inputs: ChainInputs) -> str:
        cam = inputs.rig_cameras[k].camera
        s = float(x[0])
        where = f" from {source}" if source else ""
        return (f"Recalibrate camera {frame}: its intrinsics{where} have the focal length of another lens "
                f"(x{1.0 / s:.4g}); the K that fits is fx {cam.fx * s:.1f}, fy {cam.fy * s:.1f}, cx {cam.cx:.1f}, "
                f"cy {cam.cy:.1f}{note}.")

    return _model(k, frame, "intrinsics", Fault.INTRINSICS, HopName.PIXEL_TO_CAMERA, x0=(1.0,),
                  lower=(SCALE_BOUNDS[0],), upper=(SCALE_BOUNDS[1],), x_scale=(0.01,),
                  apply=lambda p, x: p.with_camera(k, focal_scale=float(x[0])),
                  estimate=lambda x, mode, inputs: ScaleEstimate(name="scale", value=round(1.0 / float(x[0]), 6),
                                                                 variant="focal"), fix=fix,
                  tolerance=_within_scale)


def _depth(k: int, frame: str, note: str) -> FaultModel:
    def fix(x: FloatArray, mode: Mode, inputs: ChainInputs) -> str:
        f = float(x[0])
        return (f"Camera {frame}'s depths are off by x{1.0 / f:.4g}: scale them by {f:.6g} (its tag sizes in "
                f"evidence.tag_size_m, or its depth units){note}.")

    return _model(k, frame, "depth_scale", Fault.DEPTH_SCALE, HopName.PIXEL_TO_CAMERA, x0=(1.0,),
                  lower=(SCALE_BOUNDS[0],), upper=(SCALE_BOUNDS[1],), x_scale=(0.01,),
                  apply=lambda p, x: p.with_camera(k, depth_factor=float(x[0])),
                  estimate=lambda x, mode, inputs: ScaleEstimate(name="factor", value=round(1.0 / float(x[0]), 6)),
                  fix=fix, tolerance=_within_scale)


def _parent_from_body(inputs: ChainInputs, parent: str) -> FloatArray:
    """The rotation of the body in a mount's parent frame (identity when the parent is the body)."""
    if parent == inputs.frames.body:
        return np.array([0.0, 0.0, 0.0, 1.0])
    lookup = inputs.buffer.lookup(parent, inputs.frames.body, inputs.stamp_ns[:1])
    return lookup.quat_xyzw[0] if bool(lookup.ok[0]) else np.array([0.0, 0.0, 0.0, 1.0])


def _numbers(values: FloatArray) -> str:
    return "[" + ", ".join(f"{float(v):.6f}" for v in values) + "]"


def _mount_text(parent: str, child: str, xyz: FloatArray, quat: FloatArray, mounts: Mapping[str, Mount]) -> str:
    """The mount as the chain writes it (its ``mounts:`` entry, in the rotation key it used), else as a static
    transform publisher command."""
    xyz = np.asarray(xyz, dtype=float)
    quat = np.asarray(quat, dtype=float)
    entry = mounts.get(child)
    if entry is not None:
        rotation: Callable[[FloatArray], FloatArray] = {"rpy": quat_to_rpy, "rotvec": quat_to_rotvec}.get(
            entry.form, lambda q: q)
        return (f"`mounts: [{{parent: {parent}, child: {child}, xyz: {_numbers(xyz)}, "
                f"{entry.form}: {_numbers(rotation(quat))}}}]`")
    rpy = quat_to_rpy(quat)
    return (f"`ros2 run tf2_ros static_transform_publisher --x {xyz[0]:.6f} --y {xyz[1]:.6f} --z {xyz[2]:.6f} "
            f"--roll {rpy[0]:.6f} --pitch {rpy[1]:.6f} --yaw {rpy[2]:.6f} --frame-id {parent} "
            f"--child-frame-id {child}`")


__all__ = ["SCALE_BOUNDS", "TRANSLATION_BOUND_M", "rig_models"]
