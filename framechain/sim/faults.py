"""The chain three ways, the truth, the recorded data and the robot's computation, and the faults injected into
the last two (:class:`~framechain.sim.spec.InjectedFault`: ``where="data"`` or ``"robot"``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from framechain.arrays import FloatArray
from framechain.catalogue import Fault
from framechain.geometry.conventions import OPTICAL_FROM_LINK_QUAT_XYZW
from framechain.sim.spec import (
    BODY_FRAME,
    DEPTH_OPTICAL_FRAME,
    FOOTPRINT_FRAME,
    MOUNT_FRAME,
    InjectedFault,
    SceneError,
    SceneSpec,
)

__all__ = ["ChainParams", "faulty_params", "inject", "inject_data"]


@dataclass(frozen=True)
class ChainParams:
    """One version of the chain: the truth, what was recorded, or what the robot used."""

    K: FloatArray
    depth_factor: float = 1.0
    mount_quat: FloatArray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    mount_offset: FloatArray = field(default_factory=lambda: np.zeros(3))  # added to the mount's position (m)
    optical_quat: FloatArray = field(default_factory=lambda: np.array(OPTICAL_FROM_LINK_QUAT_XYZW))
    cam_permutation: FloatArray = field(default_factory=lambda: np.eye(3))
    skip_optical_edge: bool = False  # camera_link looked up for optical points
    #: the frame the detections and CameraInfo name (None: the optical frame they are really in)
    detections_frame: str | None = None
    sibling_optical: bool = False  # the depth imager's optical frame looked up for colour points
    pose_offset_ns: int = 0
    hold_ns: int | None = None  # zero-order hold of the odom sample at or before tau - hold
    world: str = "map"
    body: str = BODY_FRAME
    invert_camera: bool = False
    invert_pose: bool = False


def faulty_params(spec: SceneSpec, truth: ChainParams) -> tuple[ChainParams, ChainParams]:
    """The chain as recorded in the data and as the robot used it: the truth with the faults injected."""
    recorded, robot = truth, truth
    if any(f.used_frame == DEPTH_OPTICAL_FRAME for f in spec.faults) and not np.any(spec.optical_xyz):
        raise SceneError("wrong_camera_frame needs the colour optical frame off camera_link (optical_xyz not zero)")
    for fault in spec.faults:
        if fault.where == "robot":
            robot = inject(robot, fault, truth)
        else:
            recorded = inject_data(recorded, fault, truth)
    return recorded, robot


def inject(params: ChainParams, fault: InjectedFault, truth: ChainParams) -> ChainParams:
    """A fault in the robot's computation: the chain as the robot ran it differs from the truth."""
    p = fault.params
    kind = fault.kind
    if kind == Fault.LATENCY:
        if "hold_s" in p:
            return replace(params, hold_ns=round(float(p["hold_s"]) * 1e9))
        return replace(params, pose_offset_ns=round(float(p["offset_s"]) * 1e9))
    if kind == Fault.ROTATION_ERROR:
        error = Rotation.from_rotvec(np.deg2rad(float(p["angle_deg"])) * _unit(p.get("axis", (0, 0, 1))))
        return replace(params, mount_quat=(error * Rotation.from_quat(truth.mount_quat)).as_quat())
    if kind == Fault.MISSING_ROTATION:
        return replace(params, mount_quat=np.array([0.0, 0.0, 0.0, 1.0]))
    if kind == Fault.TRANSLATION_ERROR:
        return replace(params, mount_offset=np.asarray(p["offset_m"], dtype=float))
    if kind == Fault.AXIS_FLIP:
        if fault.used_frame is not None:
            if fault.used_frame != MOUNT_FRAME:
                raise SceneError(f"axis_flip used={fault.used_frame!r}: only {MOUNT_FRAME!r} can stand in for the "
                                 "optical frame")
            return replace(params, skip_optical_edge=True)
        return replace(params, cam_permutation=np.asarray(p["permutation"], dtype=float))
    if kind == Fault.DEPTH_SCALE:
        return replace(params, depth_factor=float(p["factor"]))
    if kind == Fault.INTRINSICS:
        k = truth.K.copy()
        if p.get("variant") == "focal":  # another lens: the focal length alone
            k[:2, :2] *= float(p["scale"])
        else:
            k[:2, :] *= float(p["scale"])  # the K of another resolution: focal and principal point scale
        return replace(params, K=k)
    if kind == Fault.WRONG_WORLD_FRAME:
        if fault.used_frame == FOOTPRINT_FRAME:
            return replace(params, body=FOOTPRINT_FRAME)
        if fault.used_frame != "odom":
            raise SceneError(f"wrong_world_frame used={fault.used_frame!r}: 'odom' or {FOOTPRINT_FRAME!r}")
        return replace(params, world="odom")
    if kind == Fault.WRONG_CAMERA_FRAME:
        if fault.used_frame != DEPTH_OPTICAL_FRAME:
            raise SceneError(f"wrong_camera_frame used={fault.used_frame!r}: only {DEPTH_OPTICAL_FRAME!r} is published")
        return replace(params, sibling_optical=True)
    if kind == Fault.INVERTED_TRANSFORM:
        if fault.hop == "body_to_world":
            return replace(params, invert_pose=True)
        return replace(params, invert_camera=True)
    raise SceneError(f"unknown fault {kind}")


def inject_data(params: ChainParams, fault: InjectedFault, truth: ChainParams) -> ChainParams:
    """A fault in the recorded data: what the log says differs from what the robot used."""
    robot_only = (
        fault.kind == Fault.WRONG_WORLD_FRAME
        or (fault.kind == Fault.INVERTED_TRANSFORM and fault.hop == "body_to_world")
        or (fault.used_frame is not None and fault.kind != Fault.AXIS_FLIP)
        or "hold_s" in fault.params
    )
    if robot_only:
        raise SceneError(f"{fault.kind.value} at {fault.hop} ({fault.params}) is a fault of the robot's computation "
                         "only; drop @data")
    if fault.kind == Fault.AXIS_FLIP and fault.used_frame is not None:
        # The detections (and their CameraInfo) name camera_link while their pixels are optical: the
        # recorded data skips the optical edge (a driver configured with the link as its frame_id).
        if fault.used_frame != MOUNT_FRAME:
            raise SceneError(f"axis_flip used={fault.used_frame!r}: only {MOUNT_FRAME!r} can stand in for the "
                             "optical frame")
        return replace(params, detections_frame=MOUNT_FRAME)
    if fault.kind == Fault.AXIS_FLIP:
        # A recorded rotation can only permute axes properly (det +1): the optical edge published wrong.
        perm = np.asarray(fault.params["permutation"], dtype=float)
        if not np.isclose(np.linalg.det(perm), 1.0):
            raise SceneError("a recorded axis flip must be a proper rotation (det +1)")
        wrong = Rotation.from_quat(truth.optical_quat) * Rotation.from_matrix(perm)
        return replace(params, optical_quat=wrong.as_quat())
    return inject(params, fault, truth)


def _unit(axis: Sequence[float]) -> FloatArray:
    a = np.asarray(axis, dtype=float)
    out: FloatArray = a / np.linalg.norm(a)
    return out
