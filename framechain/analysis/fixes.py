"""The fix for each finding, in one sentence a robotics engineer can act on."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from framechain.analysis.chain_model import ChainInputs
from framechain.analysis.faults import Mode
from framechain.replay import HopName
from framechain.replay.catalogue import Fault

FloatArray = npt.NDArray[np.float64]


def corrected_mount(inputs: ChainInputs, x: FloatArray, mode: Mode) -> tuple[str, str, FloatArray, FloatArray]:
    """The camera mount as it should be: (parent, child, xyz, rpy in radians).

    The mount is the edge above the optical frame when the camera frame hangs from a camera link
    by a pure rotation (the REP-103 optical edge); otherwise the body-to-camera transform itself.
    As-run faults keep the recorded rotation (the robot should use it); corrections apply ``x``.
    """
    recorded = Rotation.from_quat(inputs.q_bc[0])
    right = recorded if mode == "as_run" else Rotation.from_rotvec(x) * recorded
    t_bc = inputs.t_bc[0]
    path = inputs.buffer.path(inputs.frames.body, inputs.frames.camera)
    first = path.hops[0] if path.hops else None
    if first is not None and not first.inverse and first.child == inputs.frames.camera:
        edge = inputs.buffer.edges[first.child]
        if edge.is_static and not edge.translation[0].any():
            link_from_optical = Rotation.from_quat(edge.quat_xyzw[0])
            mount = right * link_from_optical.inv()
            return inputs.frames.body, edge.parent, t_bc, mount.as_euler("xyz")
    return inputs.frames.body, inputs.frames.camera, t_bc, right.as_euler("xyz")


def _origin(xyz: FloatArray, rpy: FloatArray) -> str:
    return f'<origin xyz="{xyz[0]:.4f} {xyz[1]:.4f} {xyz[2]:.4f}" rpy="{rpy[0]:.5f} {rpy[1]:.5f} {rpy[2]:.5f}"/>'


def _publisher(parent: str, child: str, xyz: FloatArray, rpy: FloatArray) -> str:
    return (
        f"ros2 run tf2_ros static_transform_publisher --x {xyz[0]:.4f} --y {xyz[1]:.4f} --z {xyz[2]:.4f} "
        f"--roll {rpy[0]:.5f} --pitch {rpy[1]:.5f} --yaw {rpy[2]:.5f} --frame-id {parent} --child-frame-id {child}"
    )


def fix_for(
    fault: Fault, hop: HopName, estimate: Mapping[str, Any], inputs: ChainInputs, x: FloatArray, mode: Mode
) -> str:
    """One actionable sentence for a finding."""
    frames = inputs.frames
    if fault in (Fault.MISSING_ROTATION, Fault.ROTATION_ERROR):
        parent, child, xyz, rpy = corrected_mount(inputs, x, mode)
        lead = (
            "Use the full recorded extrinsic (rotation included) in the robot's camera-to-body step"
            if mode == "as_run"
            else "Correct the camera mount calibration"
        )
        return f"{lead}: {parent} -> {child} {_origin(xyz, rpy)}, i.e. `{_publisher(parent, child, xyz, rpy)}`."
    if fault == Fault.LATENCY:
        offset_ms = float(estimate["offset_s"]) * 1e3
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
    if fault == Fault.AXIS_FLIP:
        return (
            f"Transform the point from {frames.camera} (x right, y down, z forward, the detection's header.frame_id), "
            f"not from a body-convention camera frame; the axes used were permuted as {estimate['permutation']}."
        )
    if fault == Fault.DEPTH_SCALE:
        factor = float(estimate["factor"])
        hint = " (16UC1 depth is millimetres: multiply by 0.001)" if 500 < factor < 2000 else ""
        return f"Scale depth by {1.0 / factor:.6g} before back-projecting{hint}."
    if fault == Fault.INTRINSICS:
        scale = float(estimate["scale"])
        return (
            f"Use the CameraInfo of the stream the detections came from ({inputs.camera.width}x{inputs.camera.height}, "
            f"fx {inputs.camera.fx:.1f}); the K used had its focal length scaled by {scale:.4g}."
        )
    if fault == Fault.WRONG_WORLD_FRAME:
        return (
            f"Transform into {estimate['meant']!r}, not {estimate['used']!r}: the error follows the map <-> odom drift."
        )
    if fault == Fault.INVERTED_TRANSFORM:
        if hop == HopName.CAMERA_TO_BODY:
            return (
                f"Use T_{frames.body}_{frames.camera} = lookupTransform(target={frames.body}, source={frames.camera}), "
                f"not its inverse."
            )
        return (
            f"Use T_{frames.world}_{frames.body} = lookupTransform(target={frames.world}, source={frames.body}), "
            f"not its inverse."
        )
    return "No fix known for this fault."
