"""The fix for each finding, in one sentence a robotics engineer can act on."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from framechain.analysis.model.chain import ChainInputs
from framechain.analysis.model.estimates import (
    Estimate,
    FrameEstimate,
    InvertedEstimate,
    LatencyEstimate,
    PermutationEstimate,
    RotationEstimate,
    ScaleEstimate,
    TranslationEstimate,
    axis_text,
)
from framechain.analysis.model.fault import Mode
from framechain.analysis.model.faults import rotation_verdict
from framechain.arrays import FloatArray
from framechain.catalogue import Fault, HopName
from framechain.geometry.rotations import quat_from_rotvec, quat_multiply, quat_to_rpy


@dataclass(frozen=True)
class FixContext:
    """Where the inputs a fix blames came from (the defaults say nothing is known)."""

    camera_source: str = ""  # the camera table's source: a CameraInfo topic or a calibration file
    camera_from_file: bool = False  # the intrinsics came from a calibration file, not a recorded CameraInfo
    depth_from_images: bool = False  # most depths were sampled from depth images (not given by the detections)
    depth_from_tag_size: bool = False  # the chain declares tag or marker sizes (depth by PnP from corners)


def corrected_mount(inputs: ChainInputs, x: FloatArray, mode: Mode) -> tuple[str, str, FloatArray, FloatArray] | None:
    """The camera mount edge as it should be: (parent, link, xyz, rpy in radians), or None without a mount.

    The edge is the static one the camera hangs from, in its own parent frame (``base_link ->
    camera_link``, ``mast -> camera_link``, ``flange -> wrist_link``), so the fix never gives a
    frame a second parent. When the robot's mount was wrong the recorded one is right; when the
    recorded one was wrong, the fitted rotation corrects it.
    """
    mount = inputs.mount
    if mount is None:
        return None
    _fault, faulty = rotation_verdict(x, mode, inputs)
    recorded = mount.q_parent_link
    right = recorded if faulty == "as_run" else quat_multiply(recorded, quat_from_rotvec(np.asarray(x, dtype=float)))
    return mount.parent, mount.link, mount.t_parent_link, quat_to_rpy(right)


def _origin(xyz: FloatArray, rpy: FloatArray) -> str:
    return f'<origin xyz="{xyz[0]:.4f} {xyz[1]:.4f} {xyz[2]:.4f}" rpy="{rpy[0]:.5f} {rpy[1]:.5f} {rpy[2]:.5f}"/>'


def _publisher(parent: str, child: str, xyz: FloatArray, rpy: FloatArray) -> str:
    return (
        f"ros2 run tf2_ros static_transform_publisher --x {xyz[0]:.4f} --y {xyz[1]:.4f} --z {xyz[2]:.4f} "
        f"--roll {rpy[0]:.5f} --pitch {rpy[1]:.5f} --yaw {rpy[2]:.5f} --frame-id {parent} --child-frame-id {child}"
    )


def fix_for(
    fault: Fault, hop: HopName, estimate: Estimate, inputs: ChainInputs, x: FloatArray, mode: Mode,
    *, context: FixContext | None = None,
) -> str:
    """One actionable sentence for a finding (``context`` says where the camera model and depths came from)."""
    context = context or FixContext()
    if isinstance(estimate, RotationEstimate):
        return _rotation_fix(fault, estimate, inputs, x, mode)
    if isinstance(estimate, LatencyEstimate):
        return _latency_fix(hop, estimate, inputs, mode)
    if isinstance(estimate, PermutationEstimate):
        return _permutation_fix(estimate, inputs, mode)
    if isinstance(estimate, ScaleEstimate):
        return _scale_fix(estimate, inputs, mode, context)
    if isinstance(estimate, FrameEstimate):
        return _frame_fix(fault, estimate, inputs, mode)
    if isinstance(estimate, InvertedEstimate):
        return _inverted_fix(hop, estimate, inputs)
    if isinstance(estimate, TranslationEstimate):
        return _translation_fix(estimate, inputs, x, mode)
    return "No fix known for this fault."


def _rotation_fix(fault: Fault, estimate: RotationEstimate, inputs: ChainInputs, x: FloatArray, mode: Mode) -> str:
    mount = corrected_mount(inputs, x, mode)
    if mount is None:
        return (f"Correct the camera-to-body rotation by {estimate.angle_deg:.2f} deg about "
                f"{axis_text(estimate.axis)} ({estimate.axis_frame} frame).")
    parent, child, xyz, rpy = mount
    if estimate.faulty == "as run" and fault == Fault.ROTATION_ERROR:
        # Logged points against the log cannot say which of the two mounts is the calibrated one.
        used = quat_to_rpy(quat_multiply(inputs.mount.q_parent_link,  # type: ignore[union-attr]
                                         quat_from_rotvec(np.asarray(x, dtype=float))))
        angle = estimate.angle_deg
        return (f"The robot's mount and the recorded {parent} -> {child} differ by {angle:.2f} deg; "
                f"the recorded one is {_origin(xyz, rpy)} (`{_publisher(parent, child, xyz, rpy)}`), the robot "
                f"used {_origin(xyz, used)}: keep the calibrated one in both (a reference or a "
                f"static target in the log tells which).")
    if estimate.faulty == "as run":
        lead = (f"The robot's camera-to-body step used a wrong mount; use the recorded {parent} -> {child} "
                f"(rotation included)")
    else:
        lost = " has no rotation" if fault == Fault.MISSING_ROTATION else " is off"
        lead = f"The recorded mount {parent} -> {child}{lost}; publish (or calibrate to) the corrected one"
    return f"{lead}: {_origin(xyz, rpy)}, i.e. `{_publisher(parent, child, xyz, rpy)}`."


def _translation_fix(estimate: TranslationEstimate, inputs: ChainInputs, x: FloatArray, mode: Mode) -> str:
    """The mount's position: the recorded one (the robot's was off), or the recorded one corrected."""
    along = axis_text(_unit(estimate.offset_m).tolist())
    off = f"{estimate.distance_m * 1e3:.1f} mm off in position (along {along} of {estimate.frame})"
    mount = inputs.mount
    if mount is None:
        return f"The camera is {off}: move its position in {inputs.frames.body} by {_xyz(-np.asarray(x))} m."
    rpy = quat_to_rpy(mount.q_parent_link)
    recorded = np.asarray(mount.t_parent_link, dtype=float)
    parent, child = mount.parent, mount.link
    if mode == "as_run":
        return (f"The robot's camera-to-body step used a mount {off}; use the recorded {parent} -> {child}: "
                f"{_origin(recorded, rpy)}, i.e. `{_publisher(parent, child, recorded, rpy)}` (the robot used xyz "
                f"{_xyz(recorded + np.asarray(x, dtype=float))}).")
    right = recorded + np.asarray(x, dtype=float)
    return (f"The recorded mount {parent} -> {child} is {off}; publish (or calibrate to) the corrected one: "
            f"{_origin(right, rpy)}, i.e. `{_publisher(parent, child, right, rpy)}`.")


def _xyz(values: FloatArray) -> str:
    return "[" + ", ".join(f"{float(v):.4f}" for v in values) + "]"


def _unit(vector: tuple[float, float, float]) -> FloatArray:
    v = np.asarray(vector, dtype=float)
    out: FloatArray = v / max(float(np.linalg.norm(v)), 1e-12)
    return out


def _latency_fix(hop: HopName, estimate: LatencyEstimate, inputs: ChainInputs, mode: Mode) -> str:
    frames = inputs.frames
    offset_ms = estimate.offset_s * 1e3
    if hop == HopName.CAMERA_TO_BODY:
        return (
            f"Look up {frames.body} <- {frames.camera} at the detection's header.stamp: the camera pose used was "
            f"{abs(offset_ms):.1f} ms {'older' if offset_ms < 0 else 'newer'} than the image."
        )
    if mode == "correction":
        return (
            f"The detections are stamped {abs(offset_ms):.1f} ms {'late' if offset_ms < 0 else 'early'}: "
            f"correct the camera clock or its stamping offset, then look up {frames.world} <- {frames.body} "
            "at header.stamp."
        )
    return (
        f"Look up {frames.world} <- {frames.body} at the detection's header.stamp (tf2 lookupTransform with "
        f"that time, waiting for the transform) instead of the pose {abs(offset_ms):.1f} ms "
        f"{'older' if offset_ms < 0 else 'newer'} that was used."
    )


def _permutation_fix(estimate: PermutationEstimate, inputs: ChainInputs, mode: Mode) -> str:
    camera = inputs.frames.camera
    if mode == "correction":
        return (f"The recorded rotation above {camera} permutes its axes as {_rows(estimate)}: "
                f"publish the REP-103 optical rotation (q_xyzw -0.5 0.5 -0.5 0.5, rpy -pi/2 0 -pi/2) from the camera "
                f"link to {camera}.")
    return (
        f"Transform the point from {camera} (x right, y down, z forward, the detection's header.frame_id), "
        f"not from a body-convention camera frame; the axes used were permuted as {_rows(estimate)}."
    )


def _scale_fix(estimate: ScaleEstimate, inputs: ChainInputs, mode: Mode, context: FixContext) -> str:
    scale = estimate.value
    cam = inputs.camera
    if estimate.name == "factor":
        return _depth_fix(scale, context)
    if mode != "correction":
        return (f"Use the CameraInfo of the stream the detections came from ({cam.width}x{cam.height}, "
                f"fx {cam.fx:.1f}); the K used had its focal length scaled by {scale:.4g}.")
    principal = estimate.variant == "resolution"
    cx, cy = (cam.cx / scale, cam.cy / scale) if principal else (cam.cx, cam.cy)
    other = "resolution" if principal else "lens"
    fitted = f"fx {cam.fx / scale:.1f}, fy {cam.fy / scale:.1f}, cx {cx:.1f}, cy {cy:.1f}"
    if context.camera_from_file:
        return (f"The intrinsics from {context.camera_source} are those of another {other} (focal length "
                f"x{scale:.4g}); the K that fits is {fitted}: put the calibration of the stream the detections "
                f"came from in that file.")
    recorded = f"CameraInfo on {context.camera_source}" if context.camera_source else "CameraInfo"
    return (f"The recorded {recorded} has the K of another {other} (focal length x{scale:.4g}); the K that "
            f"fits is {fitted}: publish the calibration of the stream the detections came from.")


def _frame_fix(fault: Fault, estimate: FrameEstimate, inputs: ChainInputs, mode: Mode) -> str:
    frames = inputs.frames
    if estimate.hop == HopName.CAMERA_TO_BODY.value:
        return _camera_frame_fix(estimate, frames.body, mode)
    if frames.body in (estimate.used, estimate.meant):
        if mode == "correction":
            return (f"The recorded chain puts the body at {estimate.used!r} where the camera hangs from "
                    f"{estimate.meant!r}: transform through {estimate.meant!r}.")
        return (f"Look up {frames.world} <- {estimate.meant} (tf2 lookupTransform(target={frames.world}, "
                f"source={estimate.meant}, header.stamp)), not {frames.world} <- {estimate.used}: the points are "
                f"{estimate.meant} points{_edges_text(estimate)}.")
    if fault == Fault.WRONG_WORLD_FRAME:
        return f"Transform into {estimate.meant!r}, not {estimate.used!r}: the error follows the map <-> odom drift."
    dropped = f" (the path differs by {_skipped_text(estimate)})" if estimate.skipped else ""
    return f"At {estimate.hop}, look up {estimate.meant!r}, not {estimate.used!r}{dropped}."


def _inverted_fix(hop: HopName, estimate: InvertedEstimate, inputs: ChainInputs) -> str:
    frames = inputs.frames
    if estimate.edge is not None:
        parent, child = estimate.edge
        return (f"The edge {parent} -> {child} is recorded inverted (T_{child}_{parent} where T_{parent}_{child} is "
                f"meant): publish it the other way round (invert its translation and rotation).")
    if hop == HopName.CAMERA_TO_BODY:
        return (f"Use T_{frames.body}_{frames.camera} = lookupTransform(target={frames.body}, source={frames.camera}), "
                f"not its inverse.")
    return (f"Use T_{frames.world}_{frames.body} = lookupTransform(target={frames.world}, source={frames.body}), "
            f"not its inverse.")


def _depth_fix(factor: float, context: FixContext) -> str:
    """Depth scaled by ``factor``: the depth images' units, or (depths from detections) tag size or odometry scale."""
    undo = f"Scale depth by {1.0 / factor:.6g} before back-projecting"
    if context.depth_from_images:
        hint = " (16UC1 depth is millimetres: multiply by 0.001)" if 500 < factor < 2000 else ""
        return f"{undo}{hint}: the depth images' units or depth_scale are off by x{factor:.4g}."
    if context.depth_from_tag_size:
        # A depth from a square marker's corners (PnP) scales with the marker size the chain declares,
        # and a scale error of the odometry (VIO) looks the same against a static target or reference.
        return (f"{undo}: either the declared tag size is off (declare sizes {1.0 / factor:.4g} times those in "
                f"evidence.tag_size_m or markers.size_m: measure the black square's side) or the odometry/VIO "
                f"scale is off by x{factor:.4g} (check it against a known distance).")
    return (f"{undo}: the detector's depth is off by x{factor:.4g} (or the odometry/VIO scale is; check it against "
            "a known distance).")


def _rows(estimate: PermutationEstimate) -> str:
    return str([list(row) for row in estimate.permutation])


def _edges_text(estimate: FrameEstimate) -> str:
    if not estimate.skipped:
        return ""
    return f" (the lookup skipped {_skipped_text(estimate)})"


def _skipped_text(estimate: FrameEstimate) -> str:
    return ", ".join(f"{p} -> {c}" for p, c in estimate.skipped)


def _camera_frame_fix(estimate: FrameEstimate, body: str, mode: Mode) -> str:
    """Name the frame to look up on the camera-to-body hop (the optical frame, usually)."""
    if mode == "correction":
        return (f"The detections say they are in {estimate.used} but their points are in {estimate.meant}: set the "
                f"detections' header.frame_id to {estimate.meant} (or look up {body} <- {estimate.meant}).")
    optical = estimate.meant.endswith(("_optical_frame", "_optical"))
    why = " (x right, y down, z forward: the detection's header.frame_id)" if optical else ""
    return (f"Look up {body} <- {estimate.meant}{why}, not {body} <- {estimate.used}: "
            f"`tf_buffer.lookup_transform('{body}', '{estimate.meant}', header.stamp)`{_edges_text(estimate)}.")
