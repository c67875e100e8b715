"""What a chain says of its cameras: each camera's calibration file (``calibration:``), the markers to find
in its images (``evidence.markers``), its latency budget, and a rig's cameras, each with topics of its own
(``cameras:``). The keys are those of CHAIN.yaml (:mod:`framechain.config.chain`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from framechain.config import plausible
from framechain.config.schema import Section, as_list, dataclass_keys

__all__ = [
    "CalibrationSource",
    "MarkerSpec",
    "RigCamera",
    "calibration_source",
    "calibration_sources",
    "latency_budget",
    "marker_spec",
    "rig_cameras",
]


@dataclass(frozen=True)
class CalibrationSource:
    """A camera calibration file (ROS camera_info, Kalibr camchain, OpenCV YAML) for one camera.

    ``camera`` picks the camera in a file of several (Kalibr: by name, rostopic or tagtopic);
    ``frame`` is the camera's optical frame (default: the chain's camera frame).
    """

    file: str
    camera: str | None = None
    frame: str | None = None


@dataclass(frozen=True)
class MarkerSpec:
    """Markers to find in a camera's images (``topics.image``): an OpenCV dictionary name and the side length
    in metres."""

    dictionary: str
    size_m: float | None = None


@dataclass(frozen=True)
class RigCamera:
    """One camera of a rig: its optical frame, the topics that are its own (its detections decide which
    camera an observation belongs to), its calibration, markers and latency budget (None: the chain's)."""

    frame: str
    detections: str
    calibration: CalibrationSource | None = None
    camera_info: str | None = None
    image: str | None = None
    depth: str | None = None
    markers: MarkerSpec | None = None
    latency_budget_s: float | None = None

    def topics(self) -> tuple[str, ...]:
        """Every topic of this camera (detections, camera_info, image, depth)."""
        return tuple(t for t in (self.detections, self.camera_info, self.image, self.depth) if t)


def latency_budget(section: Section) -> float | None:
    """``latency_budget_s`` of a chain, of a rig camera or of robot.yaml's ``chain:``: seconds, 0 or more."""
    return section.number("latency_budget_s", minimum=0.0, unit="s", check=plausible.latency_budget)


def marker_spec(section: Section) -> MarkerSpec | None:
    """The ``markers`` mapping of ``section`` (None: not given)."""
    if "markers" not in section:
        return None
    markers = section.section("markers", dataclass_keys(MarkerSpec))
    name = markers.name("dictionary")
    if name is None:
        markers.fail("needs dictionary: an OpenCV marker dictionary such as DICT_5X5_1000")
    return MarkerSpec(name, markers.number("size_m", positive=True, unit="m", check=plausible.tag_size))


def calibration_source(top: Section, entry: Any, here: str, *, frame: str | None = None) -> CalibrationSource:
    """``{file, camera, frame}`` (or a file name); a rig camera's entry has its frame and names none."""
    known = dataclass_keys(CalibrationSource) - ({"frame"} if frame else set())
    what = "a file name or {file, camera}" if frame else "a file name or {file, camera, frame}"
    source = top.child({"file": entry} if isinstance(entry, str) else entry, here, known, what=what)
    file = source.name("file", required=False, what="a file name")
    if file is None:
        source.fail("needs file: the calibration file (relative to the chain file)")
    return CalibrationSource(file, source.name("camera", what="a camera name"), frame or source.frame("frame"))


def calibration_sources(top: Section) -> tuple[CalibrationSource, ...]:
    """The chain's ``calibration:``, one entry or a list; at most one may leave its frame to frames.camera."""
    raw = top.get("calibration")
    out: list[CalibrationSource] = []
    for i, entry in enumerate(as_list(raw)):
        here = f"calibration[{i}]" if isinstance(raw, list | tuple) else "calibration"
        out.append(calibration_source(top, entry, here))
    defaulted = [i for i, c in enumerate(out) if c.frame is None]
    if len(defaulted) > 1:
        top.fail(f"calibration[{defaulted[1]}]: give frame: (the camera's optical frame); only one entry can "
                 "default to frames.camera")
    return tuple(out)


_RIG_CAMERA_KEYS = dataclass_keys(RigCamera)


def rig_cameras(top: Section) -> tuple[RigCamera, ...]:
    """``cameras:``, a list of ``{frame, detections, calibration, camera_info, image, depth, markers,
    latency_budget_s}``; frames and topics are each one camera's."""
    if "cameras" not in top:
        return ()
    raw = top.get("cameras")
    if not isinstance(raw, list | tuple) or not raw:
        top.expected("cameras", "a list of cameras, each {frame, detections, calibration, ...}", raw)
    out: list[RigCamera] = []
    for i, entry in enumerate(raw):
        cam = top.child(entry, f"cameras[{i}]", _RIG_CAMERA_KEYS, what="{frame, detections, calibration, ...}")
        frame = cam.frame("frame", required=True, hint="the camera's optical frame") or ""
        calibration = cam.get("calibration")
        markers = marker_spec(cam)
        out.append(RigCamera(
            frame=frame,
            detections=cam.name("detections", required=True, hint="the camera's detections topic",
                                what="a topic name") or "",
            calibration=None if calibration is None else calibration_source(
                top, calibration, cam.path("calibration"), frame=frame),
            camera_info=cam.name("camera_info", what="a topic name"), image=cam.name("image", what="a topic name"),
            depth=cam.name("depth", what="a topic name"), markers=markers,
            latency_budget_s=latency_budget(cam),
        ))
        if markers is not None and out[-1].image is None:
            cam.fail("markers needs image (the camera's image topic to find them in)")
    for key in ("frame", "detections"):
        seen: dict[str, int] = {}
        for i, c in enumerate(out):
            value = getattr(c, key)
            if value in seen:
                top.fail(f"cameras[{i}] and cameras[{seen[value]}] have the same {key} {value!r}")
            seen[value] = i
    return tuple(out)
