"""What a generated scene is asked to be: its frames and topics, the faults injected and where they live, the
findings attribution should report for them, and the spec that shapes an episode (:mod:`framechain.sim.scene`
generates it)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from framechain.catalogue import FAULT_HOPS, Fault
from framechain.config.chain import ChainTopics, HopTopics
from framechain.errors import FramechainError

__all__ = [
    "BODY_FRAME",
    "COLOR_TOPIC",
    "DEPTH_OPTICAL_FRAME",
    "FOOTPRINT_FRAME",
    "HOP_TOPICS",
    "MOUNT_FRAME",
    "REALSENSE_OPTICAL_FRAME",
    "REALSENSE_OPTICAL_XYZ",
    "REFERENCE_TOPIC",
    "START_NS",
    "TARGET_TOPIC",
    "TOPICS",
    "Evidence",
    "ExpectedFinding",
    "InjectedFault",
    "SceneError",
    "SceneSpec",
    "Where",
    "expected_finding",
]

START_NS = 1_700_000_000_000_000_000
TOPICS = ChainTopics(
    camera_info="/camera/color/camera_info", detections="/detections", depth="/camera/depth/image_rect_raw"
)
HOP_TOPICS = HopTopics(camera="/debug/point_camera", body="/debug/point_body", world="/debug/point_world")
TARGET_TOPIC = "/grasp_target"
COLOR_TOPIC = "/camera/color/image_raw"
REFERENCE_TOPIC = "/mocap/target"
MOUNT_FRAME = "camera_link"
BODY_FRAME = "base_link"
FOOTPRINT_FRAME = "base_footprint"
#: A sibling imager's optical frame at camera_link's origin (a RealSense's depth camera).
DEPTH_OPTICAL_FRAME = "camera_depth_optical_frame"
#: A RealSense's colour optical frame: its name and its offset from camera_link (metres, camera_link axes).
REALSENSE_OPTICAL_FRAME = "camera_color_optical_frame"
REALSENSE_OPTICAL_XYZ = (0.0, 0.015, 0.0)

Evidence = Literal["hops", "target", "reference", "static"]
Where = Literal["robot", "data"]


class SceneError(FramechainError):
    """A scene that cannot be generated as asked (a fault where it cannot live)."""


@dataclass(frozen=True)
class InjectedFault:
    """One fault and where it lives. Parameters by kind:

    - latency ``offset_s`` (robot: the pose used is the one at tau + offset; data: detections are
      stamped ``-offset_s`` late, so the pose that explains them is again at tau + offset); or
      ``hold_s`` (robot only, a stale pose held: the robot used the pose at the latest odom sample
      at or before tau - hold_s instead of interpolating at tau; attribution should report an
      offset of about ``-(hold_s + half an odom period)``).
    - rotation_error ``angle_deg``, ``axis`` (body frame).
    - translation_error ``offset_m`` (x, y, z in base_link): the mount's position moved by it (robot: the robot
      used it; data: /tf_static publishes it). Attribution should report ``offset_m`` itself either way.
    - missing_rotation (no parameters: the mount's rotation is dropped, the optical rotation kept).
    - axis_flip ``permutation`` (3x3 signed, applied to camera-frame points; in the data a proper
      rotation published on the optical edge); or ``used="camera_link"``, the real form: in the
      robot, it looked up camera_link instead of the optical frame, so the optical points went
      through T_base_camera_link alone, losing the optical edge's REP-103 rotation AND its
      translation; in the data, the detections and their CameraInfo name camera_link (a driver
      configured with the link as its frame_id) while their pixels are optical. Attribution should
      report ``used == "camera_link"`` either way.
    - wrong_camera_frame ``used`` (robot only, default ``"camera_depth_optical_frame"``): the robot
      looked up the depth imager's optical frame (published at camera_link's origin with the
      REP-103 rotation) for colour detections: a translation of ``-optical_xyz`` alone, so the
      scene's ``optical_xyz`` must not be zero.
    - depth_scale ``factor`` (as-run / true).
    - intrinsics ``scale`` (as-run K / true K: ``scale=2`` is the camera_info of a 1280x960
      calibration used for 640x480 images, fx, fy, cx, cy all doubled; with ``variant="focal"`` the
      focal length alone, another lens).
    - wrong_world_frame ``used`` (robot only): ``"odom"`` (the default, odom used for map) or
      ``"base_footprint"`` (the robot looked up base_footprint instead of base_link: the scene
      then publishes base_link -> base_footprint, ``footprint_height_m`` (default 0.08) below).
    - inverted_transform ``hop`` (camera_to_body, or body_to_world for the robot only); in the data,
      the mount published inverted (T_camera_link_base on the base_link -> camera_link edge).
    """

    kind: Fault
    where: Where = "robot"
    params: dict[str, Any] = field(default_factory=dict)

    @property
    def hop(self) -> str:
        if self.kind == Fault.INVERTED_TRANSFORM:
            return str(self.params.get("hop", "camera_to_body"))
        return FAULT_HOPS[self.kind].value

    @property
    def used_frame(self) -> str | None:
        """The frame the robot looked up instead of the right one, for the frame-swap forms."""
        if self.kind == Fault.WRONG_WORLD_FRAME:
            return str(self.params.get("used", "odom"))
        if self.kind == Fault.AXIS_FLIP and "used" in self.params:
            return str(self.params["used"])
        if self.kind == Fault.WRONG_CAMERA_FRAME:
            return str(self.params.get("used", DEPTH_OPTICAL_FRAME))
        return None


@dataclass(frozen=True)
class ExpectedFinding:
    """What attribution should report for one injected fault.

    ``estimate`` holds attribution.json estimate keys and their true values; ``tolerance`` the
    allowed absolute error of each numeric key (strings and lists must match exactly).
    """

    fault: str
    hop: str
    estimate: dict[str, Any]
    tolerance: dict[str, float]

    def names(self, fault: str, hop: str, estimate: Mapping[str, Any]) -> bool:
        """Whether a finding names this fault: the fault, the hop and, for frame swaps, the frame used."""
        if (fault, hop) != (self.fault, self.hop):
            return False
        return "used" not in self.estimate or estimate.get("used") == self.estimate["used"]

    def estimate_within(self, estimate: Mapping[str, Any]) -> bool:
        """Whether every expected estimate key is present and within its tolerance."""
        for key, want in self.estimate.items():
            got = estimate.get(key)
            if got is None:
                return False
            if isinstance(want, float):
                if not abs(float(got) - want) <= self.tolerance[key]:
                    return False
            elif _plain(got) != _plain(want):
                return False
        return True


def _plain(value: Any) -> Any:
    """Tuples and arrays as nested lists, so that [[1, 0], ...] equals ((1, 0), ...)."""
    if isinstance(value, tuple | list | np.ndarray):
        return [_plain(v) for v in value]
    return value


@dataclass(frozen=True)
class SceneSpec:
    """Everything that shapes a generated episode; equal specs give equal scenes."""

    seed: int = 0
    duration_s: float = 10.0
    camera_rate_hz: float = 30.0
    odom_rate_hz: float = 100.0
    drift_rate_hz: float = 50.0
    width: int = 640
    height: int = 480
    focal_px: float = 600.0
    mount_xyz: tuple[float, float, float] = (0.30, 0.0, 1.20)
    mount_pitch_deg: float = 30.0
    optical_frame: str = "camera_optical_frame"
    optical_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)  # camera_link -> optical offset
    object_world: tuple[float, float, float] = (3.0, 1.0, 0.10)
    orbit_radius_m: float = 2.4
    orbit_rate: float | None = None  # rad/s; None: drawn from the seed
    wobble_rad: float | None = None
    #: the base stays where the orbit starts (a fixed camera over a static target: no motion to show
    #: a latency, and nothing to tell a mount rotation or a scale from the target's position)
    fixed_camera: bool = False
    pixel_noise_px: float = 0.5
    depth_noise_rel: float = 0.003
    reference_noise_m: float = 0.002
    evidence: Evidence = "hops"
    depth_images: bool = False
    #: JPEG colour images on ``/camera/color/image_raw`` (the floor and the object), one per detection.
    color_images: bool = False
    faults: tuple[InjectedFault, ...] = ()


def expected_finding(spec: SceneSpec, fault: InjectedFault) -> ExpectedFinding:
    """What attribution should report for ``fault`` injected into a scene of ``spec``."""
    p = fault.params
    estimate: dict[str, Any] = {}
    tolerance: dict[str, float] = {}
    if fault.kind == Fault.LATENCY:
        if "hold_s" in p:
            # The held sample is between hold_s and hold_s + one odom period old: on average half a period more.
            period = 1.0 / spec.odom_rate_hz
            estimate["offset_s"] = -(float(p["hold_s"]) + 0.5 * period)
            tolerance["offset_s"] = 0.5 * period + 0.002
        else:
            estimate["offset_s"], tolerance["offset_s"] = float(p["offset_s"]), 0.002
    elif fault.kind == Fault.ROTATION_ERROR:
        estimate["angle_deg"], tolerance["angle_deg"] = float(p["angle_deg"]), 0.5
    elif fault.kind == Fault.TRANSLATION_ERROR:
        estimate["distance_m"], tolerance["distance_m"] = float(np.linalg.norm(p["offset_m"])), 0.005
    elif fault.kind == Fault.MISSING_ROTATION:
        estimate["angle_deg"], tolerance["angle_deg"] = float(abs(spec.mount_pitch_deg)), 0.5
    elif fault.kind == Fault.DEPTH_SCALE:
        estimate["factor"] = float(p["factor"])
        tolerance["factor"] = 0.01 * abs(estimate["factor"])
    elif fault.kind == Fault.INTRINSICS:
        estimate["scale"] = float(p["scale"])
        tolerance["scale"] = 0.01 * abs(estimate["scale"])
    elif fault.kind == Fault.AXIS_FLIP:
        if fault.used_frame is not None:
            estimate["used"] = fault.used_frame
        else:
            estimate["permutation"] = np.asarray(p["permutation"], dtype=int).tolist()
    elif fault.kind in (Fault.WRONG_WORLD_FRAME, Fault.WRONG_CAMERA_FRAME):
        estimate["used"] = fault.used_frame
    elif fault.kind == Fault.INVERTED_TRANSFORM and fault.where == "data":
        estimate["edge"] = [BODY_FRAME, MOUNT_FRAME]
    return ExpectedFinding(fault.kind.value, fault.hop, estimate, tolerance)
