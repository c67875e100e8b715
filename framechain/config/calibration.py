"""Camera calibration files: intrinsics, the link a camera is mounted on, the mount, the timing.

One YAML mapping per camera (a file of its own, or inline under ``cameras:`` in robot.yaml)::

    name: wrist                        # camera name; detections name it in their `camera` column
    frame: wrist_camera_optical_frame  # optional; default <name>_optical_frame
    intrinsics:                        # inline pinhole parameters ...
      fx: 600.0
      fy: 600.0
      cx: 320.0
      cy: 240.0
      width: 640
      height: 480
      distortion_model: plumb_bob      # optional: plumb_bob | rational_polynomial | equidistant | none
      distortion: [0.0, 0.0, 0.0, 0.0, 0.0]
    # intrinsics_file: wrist_info.yaml # ... or a ROS camera_info YAML / OpenCV calibration YAML,
                                       #     relative to this file
    mount:
      parent: gripper_link             # the URDF link (or the world frame for a scene camera)
      xyz: [0.0, -0.03, 0.02]          # metres
      rpy: [0.0, 0.0, 0.0]             # radians, fixed axes x-y-z as URDF; or quat_xyzw: [x, y, z, w],
                                       # or rotvec: [x, y, z] (radians)
      optical: false                   # required. true: the mount gives the optical frame (RDF)
                                       # directly. false: it gives a camera_link (FLU), and the
                                       # REP-103 rotation q_xyzw = (-0.5, 0.5, -0.5, 0.5) to the
                                       # optical frame is appended as <name>_link -> frame.
    video_key: observation.images.wrist  # optional dataset feature of this camera's images
    timing:                            # optional: when the camera's frames were taken
      timestamp_column: observation.images.wrist.timestamp  # per-frame camera time (s), or
      offset_s: 0.0                    # camera time = frame timestamp + offset_s
      pairing: order                   # optional: how a video's frames pair with the rows (presentation,
                                       # order or fitted); found from the files when not given
    depth:                             # optional: a per-frame depth feature of this camera
      feature: observation.depth.wrist # array feature (H, W), float metres or integer units
      scale_m: 0.001                   # metres per unit (default 1.0)

A ROS camera_info YAML (``camera_calibration_parsers``) has ``image_width``, ``image_height``,
``camera_matrix: {rows, cols, data}``, ``distortion_model``, ``distortion_coefficients``. An
OpenCV calibration YAML (``cv::FileStorage``) starts with ``%YAML:1.0`` and holds
``!!opencv-matrix`` entries ``camera_matrix`` (or ``K``/``cameraMatrix``) and
``distortion_coefficients`` (or ``D``/``dist_coeffs``/``distCoeffs``), with ``image_width``/
``image_height`` (or ``width``/``height``). A Kalibr camchain (or TagSLAM ``cameras.yaml``) maps
camera names to ``camera_model: pinhole``, ``intrinsics: [fx, fy, cx, cy]``, ``distortion_model``
(``radtan`` = plumb_bob k1 k2 p1 p2, ``equidistant`` = OpenCV fisheye k1..k4), ``distortion_coeffs``,
``resolution: [width, height]``, ``rostopic`` and ``tagtopic``; its extrinsics (``T_cam_imu``,
``T_cn_cnm1``) are not read. :func:`read_intrinsics_file` reads all three, detected by content.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from framechain.arrays import FloatArray
from framechain.config import plausible
from framechain.config.errors import CalibrationError
from framechain.config.mount import CAMERA_MOUNT_KEYS, Mount, camera_mount
from framechain.config.schema import Section, finite_number, read_yaml, show
from framechain.geometry.camera import CameraModel
from framechain.geometry.conventions import OPTICAL_FROM_LINK_QUAT_XYZW
from framechain.timeline import CameraTable

__all__ = [
    "CalibrationError",
    "CameraCalibration",
    "CameraTiming",
    "DepthSource",
    "Intrinsics",
    "load_calibration",
    "read_intrinsics_file",
]


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels, with the image size and distortion (ROS model names)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    distortion_model: str = "plumb_bob"
    distortion: tuple[float, ...] = ()
    source: str = ""
    #: Values that are plausible but unusual (fx far from fy), one line each.
    notes: tuple[str, ...] = field(default=(), compare=False)

    @property
    def K(self) -> FloatArray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def camera_model(self, frame: str = "") -> CameraModel:
        """The camera model these intrinsics declare, for the optical frame ``frame``."""
        return CameraModel(frame, self.K, self.width, self.height, self.distortion_model, np.asarray(self.distortion))


@dataclass(frozen=True)
class CameraTiming:
    """When a camera's frames were taken relative to the dataset's per-frame timestamp."""

    timestamp_column: str | None = None
    offset_s: float = 0.0
    #: How the video's frames pair with the rows, when the user forces it (None: found from the files).
    pairing: str | None = None


#: The ways a video's frames can pair with a dataset's rows (framechain.adapters.lerobot.clock).
PAIRINGS = ("presentation", "order", "fitted")


@dataclass(frozen=True)
class DepthSource:
    """A per-frame depth image feature of the dataset, and its unit in metres."""

    feature: str
    scale_m: float = 1.0


@dataclass(frozen=True)
class CameraCalibration:
    """One camera: its name and frames, intrinsics, mount, images, timing and depth."""

    name: str
    intrinsics: Intrinsics
    mount: Mount
    frame: str = ""
    video_key: str | None = None
    timing: CameraTiming = field(default_factory=CameraTiming)
    depth: DepthSource | None = None
    source: str = ""
    #: Values that are plausible but unusual, one line each (the intrinsics' included).
    notes: tuple[str, ...] = field(default=(), compare=False)

    @property
    def optical_frame(self) -> str:
        return self.frame or f"{self.name}_optical_frame"

    @property
    def link_frame(self) -> str:
        """The FLU camera_link frame (only used when the mount is not optical)."""
        return f"{self.name}_link"

    def camera_table(self) -> CameraTable:
        i = self.intrinsics
        return CameraTable.from_intrinsics(
            self.optical_frame, fx=i.fx, fy=i.fy, cx=i.cx, cy=i.cy, width=i.width, height=i.height,
            distortion_model=i.distortion_model, distortion=i.distortion, source=i.source or self.source,
        )

    def mount_edges(self) -> list[Mount]:
        """The static edges from the mount's parent to the optical frame: the mount, and below a camera_link
        the REP-103 rotation to the optical frame."""
        m = self.mount
        if m.optical:
            return [m]
        return [m, Mount(self.link_frame, self.optical_frame, (0.0, 0.0, 0.0), OPTICAL_FROM_LINK_QUAT_XYZW, True,
                         m.source)]


_TOP_KEYS = {"name", "frame", "intrinsics", "intrinsics_file", "mount", "video_key", "timing", "depth"}
_INTRINSICS_KEYS = {"fx", "fy", "cx", "cy", "width", "height", "distortion_model", "distortion"}


def load_calibration(
    raw: str | Path | Mapping[str, Any], *, name: str | None = None, base_dir: str | Path | None = None,
    source: str | None = None, where: str = "",
) -> CameraCalibration:
    """Read a camera calibration (a YAML file path, or an already-parsed mapping).

    ``name`` defaults to the file's ``name`` key, else the file stem. Relative paths in the
    calibration resolve against the file's directory (for a mapping: ``base_dir``). A mapping
    found inside another file (robot.yaml's ``cameras:``) names that file as ``source`` and its
    path in it as ``where``.
    """
    if isinstance(raw, Mapping):
        source = source or f"calibration {name or raw.get('name', '?')}"
        data: Any = raw
        folder = Path(base_dir) if base_dir is not None else Path.cwd()
        stem = ""
    else:
        path = Path(raw)
        if base_dir is not None and not path.is_absolute():
            path = Path(base_dir) / path
        source, data, folder, stem = str(path), _read_yaml(path), path.parent, path.stem
    top = Section(data, source=source, where=where, known=_TOP_KEYS, error=CalibrationError,
                  what="a camera calibration mapping")
    cam_name = name or top.name("name", what="a camera name") or stem
    if not cam_name:
        top.fail("the camera has no name")
    intrinsics = _intrinsics(top, folder)
    if "mount" not in top:
        top.fail("no mount: give mount: {parent, xyz, rpy | quat_xyzw | rotvec, optical}")
    mount = camera_mount(top.section("mount", CAMERA_MOUNT_KEYS))
    timing = top.section("timing", {"timestamp_column", "offset_s", "pairing"})
    offset_s = timing.number("offset_s", 0.0, unit="s", check=plausible.camera_offset)
    pairing = timing.name("pairing", what="a pairing")
    if pairing is not None and pairing not in PAIRINGS:
        timing.expected("pairing", f"one of {', '.join(PAIRINGS)}", pairing)
    calibration = CameraCalibration(
        name=cam_name, intrinsics=intrinsics, mount=mount, frame=top.frame("frame") or "",
        video_key=top.name("video_key", what="a feature name"),
        timing=CameraTiming(timing.name("timestamp_column", what="a column name"), offset_s or 0.0, pairing),
        # Inline intrinsics noted into this file's notes already; a file's own come with its intrinsics.
        depth=_depth(top), source=source, notes=tuple(dict.fromkeys((*intrinsics.notes, *top.notes))),
    )
    # The mount's child is the camera's optical frame, or its camera_link: named now the frame is read.
    child = calibration.optical_frame if mount.optical else calibration.link_frame
    return replace(calibration, mount=replace(mount, child=child))


def _intrinsics(top: Section, folder: Path) -> Intrinsics:
    """Inline ``intrinsics``, or ``intrinsics_file`` relative to ``folder``."""
    if "intrinsics" in top and "intrinsics_file" in top:
        top.fail("give either intrinsics or intrinsics_file, not both")
    if "intrinsics" in top:
        return _inline_intrinsics(top.section("intrinsics", _INTRINSICS_KEYS))
    if "intrinsics_file" not in top:
        top.fail("no intrinsics: give intrinsics: {fx, fy, cx, cy, width, height} or intrinsics_file")
    path = Path(top.name("intrinsics_file", what="a file name") or "")
    return read_intrinsics_file(path if path.is_absolute() else folder / path)


def _depth(top: Section) -> DepthSource | None:
    if "depth" not in top:
        return None
    depth = top.section("depth", {"feature", "scale_m"})
    feature = depth.name("feature", required=True, hint="the dataset's depth image feature", what="a feature name")
    scale = depth.number("scale_m", 1.0, positive=True, unit="metres per unit", check=plausible.depth_scale)
    return DepthSource(feature or "", 1.0 if scale is None else scale)


def _read_yaml(path: Path) -> Any:
    return read_yaml(path, error=CalibrationError, what="calibration", loader=_OpenCVLoader,
                     prepare=_strip_opencv_header)


def _inline_intrinsics(section: Section) -> Intrinsics:
    fx, fy, cx, cy, width, height = (section.number(k, required=True) or 0.0
                                     for k in ("fx", "fy", "cx", "cy", "width", "height"))
    dist = section.get("distortion", [])
    model = section.name("distortion_model", "plumb_bob" if dist else "none", what="a distortion model name")
    return _make_intrinsics(section, (fx, fy, cx, cy, width, height), model or "none", dist,
                            (section.where, section.path("distortion")))


def _make_intrinsics(section: Section, pinhole: tuple[float, float, float, float, float, float], model: str,
                     dist: Any, where: tuple[str, str]) -> Intrinsics:
    """Intrinsics ``(fx, fy, cx, cy, width, height)`` checked against each other and the image size;
    ``where`` names the intrinsics and the distortion in messages."""
    fx, fy, cx, cy, width, height = pinhole
    if not (fx > 0 and fy > 0):
        section.fail_in(where[0], f"focal lengths fx={fx} fy={fy} must be positive")
    if not (1 <= width <= 1e5 and 1 <= height <= 1e5 and float(width).is_integer() and float(height).is_integer()):
        section.fail_in(where[0], f"image size {width:g}x{height:g} must be whole numbers of pixels")
    coeffs = dist if isinstance(dist, list | tuple) else [dist]
    if len(coeffs) > 14 or not all(finite_number(c) for c in coeffs):
        section.fail_at(where[1], f"must be at most 14 finite numbers, got {show(dist)}")
    before = len(section.notes)
    section.check_plausible(where[0], lambda _: plausible.intrinsics(fx, fy, cx, cy, int(width), int(height)), None,
                            within=True)
    return Intrinsics(fx, fy, cx, cy, int(width), int(height), model, tuple(float(c) for c in coeffs),
                      section.source, tuple(section.notes[before:]))


# ------------------------------------------------------------------------------ intrinsics files


class _OpenCVLoader(yaml.SafeLoader):
    """SafeLoader that understands OpenCV's ``!!opencv-matrix`` tag."""


def _opencv_matrix(loader: yaml.SafeLoader, node: yaml.Node) -> list[list[float]]:
    if not isinstance(node, yaml.MappingNode):
        raise yaml.constructor.ConstructorError(None, None, "an opencv-matrix must be a mapping", node.start_mark)
    m = loader.construct_mapping(node, deep=True)
    try:
        rows, cols = int(m["rows"]), int(m["cols"])
        data = np.asarray(m["data"], dtype=float).reshape(rows, cols)
    except (KeyError, TypeError, ValueError, OverflowError) as err:
        raise yaml.constructor.ConstructorError(
            None, None, f"an opencv-matrix needs rows, cols and rows x cols numbers as data ({err})",
            node.start_mark) from None
    out: list[list[float]] = data.tolist()
    return out


_OpenCVLoader.add_constructor("tag:yaml.org,2002:opencv-matrix", _opencv_matrix)


def _strip_opencv_header(text: str) -> str:
    """OpenCV writes ``%YAML:1.0`` (not valid YAML 1.1) on its first line: make it a comment (so that
    YAML's line numbers stay the file's)."""
    return "#" + text if text.startswith("%YAML:") else text


def read_intrinsics_file(path: str | Path, *, camera: str | None = None) -> Intrinsics:
    """Intrinsics from a ROS camera_info YAML, a Kalibr camchain or an OpenCV calibration YAML
    (detected by content).

    ``camera`` picks one camera of a Kalibr file by name, ``rostopic`` or ``tagtopic`` (needed when
    the file holds several); for a ROS file it must match ``camera_name`` when that is given.
    """
    p = Path(path)
    source = str(p)
    if not p.is_file():  # the resolved path: a relative name alone does not say where it was looked for
        raise CalibrationError(str(p.resolve()), "calibration file not found")
    top = Section(_read_yaml(p), source=source, error=CalibrationError)
    if _is_kalibr(top.raw):
        return _kalibr_camera(top, camera)
    named = top.get("camera_name")
    if camera is not None and named is not None and str(named) != camera:
        top.fail(f"camera {camera!r} is not in the file; it holds camera_name {named!r}")
    key = _first(top, ("camera_matrix", "K", "cameraMatrix", "camera_matrix_left"))
    if key is None:
        top.fail("no camera matrix (camera_matrix, K or cameraMatrix)")
    K = top.get(key)
    if isinstance(K, Mapping):  # ROS: {rows, cols, data}
        if "data" not in K:
            top.fail(f"{key} has no data")
        K = K["data"]
    if isinstance(K, list) and all(isinstance(row, list) for row in K):  # OpenCV: rows of the matrix
        K = [x for row in K for x in row]
    kmat = np.asarray(top.vector_value(K, 9, key), dtype=float).reshape(3, 3)
    coeffs = _distortion(top)
    width, height = _image_size(top)
    model = top.name("distortion_model", what="a distortion model name") or (
        "plumb_bob" if len(coeffs) in (4, 5) else "rational_polynomial" if len(coeffs) == 8 else
        "none" if not coeffs else "plumb_bob")
    if abs(kmat[0, 1]) > 1e-9 or abs(kmat[2, 2] - 1.0) > 1e-9:
        top.fail(f"camera matrix {kmat.tolist()} is not a pinhole K (skew 0, K[2,2] = 1)")
    pinhole = (float(kmat[0, 0]), float(kmat[1, 1]), float(kmat[0, 2]), float(kmat[1, 2]), width, height)
    return _make_intrinsics(top, pinhole, model, coeffs, (key, _first(top, _DISTORTION_KEYS) or "distortion"))


_DISTORTION_KEYS = ("distortion_coefficients", "D", "dist_coeffs", "distCoeffs", "distortion")


def _distortion(top: Section) -> list[Any]:
    key = _first(top, _DISTORTION_KEYS)
    dist = top.get(key) if key is not None else []
    if isinstance(dist, Mapping):
        dist = dist.get("data", [])
    if isinstance(dist, list) and dist and all(isinstance(row, list) for row in dist):  # OpenCV: one row
        dist = [x for row in dist for x in row]
    if not isinstance(dist, list):
        top.fail_at(key or "distortion", f"must be a list of numbers, got {show(dist)}")
    return dist


def _image_size(top: Section) -> tuple[float, float]:
    width_key = _first(top, ("image_width", "width", "imageWidth"))
    height_key = _first(top, ("image_height", "height", "imageHeight"))
    if width_key is not None and height_key is not None:
        return top.number(width_key) or 0.0, top.number(height_key) or 0.0
    size_key = _first(top, ("image_size", "imageSize"))
    if size_key is None:
        top.fail("no image size (image_width/image_height or width/height)")
    size = top.get(size_key)
    if isinstance(size, list) and size and all(isinstance(row, list) for row in size):
        size = [x for row in size for x in row]
    if isinstance(size, list) and len(size) > 2:
        size = size[:2]
    width, height = top.vector_value(size, 2, size_key, what="[width, height]")
    return width, height


#: Kalibr distortion names -> ROS names (radtan is plumb_bob without k3).
_KALIBR_DISTORTION = {"radtan": "plumb_bob", "plumb_bob": "plumb_bob", "equidistant": "equidistant",
                      "fisheye": "equidistant", "rational_polynomial": "rational_polynomial", "none": "none"}


def _is_kalibr(raw: Mapping[Any, Any]) -> bool:
    """A camchain: camera names mapping to entries with a Kalibr ``intrinsics`` list."""
    return any(isinstance(v, Mapping) and isinstance(v.get("intrinsics"), list) for v in raw.values())


def _kalibr_camera(top: Section, camera: str | None) -> Intrinsics:
    entries = {str(k): v for k, v in top.raw.items() if isinstance(v, Mapping)}
    if camera is None:
        if len(entries) != 1:
            top.fail(f"{len(entries)} cameras ({', '.join(entries)}); pick one with camera: NAME (or its rostopic or "
                     "tagtopic)")
        name = next(iter(entries))
    elif camera in entries:
        name = camera
    else:
        by_topic = [k for k, v in entries.items() if camera in (v.get("rostopic"), v.get("tagtopic"))]
        if not by_topic:
            listed = ", ".join(f"{k} ({v.get('rostopic', 'no rostopic')})" for k, v in entries.items())
            top.fail(f"camera {camera!r} is not in the file; its cameras are {listed}")
        name = by_topic[0]
    entry = top.child(entries[name], name)
    model = entry.name("camera_model", "pinhole", what="a camera model name")
    if model != "pinhole":
        entry.fail(f"camera_model {model!r} is not supported (pinhole only)")
    fx, fy, cx, cy = entry.vector("intrinsics", 4, required=True, hint="[fx, fy, cx, cy]",
                                  what="[fx, fy, cx, cy], four finite numbers") or (0.0, 0.0, 0.0, 0.0)
    width, height = entry.vector("resolution", 2, required=True, hint="[width, height]",
                                 what="[width, height], two finite numbers") or (0.0, 0.0)
    coeffs = entry.get("distortion_coeffs", [])
    kalibr_model = str(entry.name("distortion_model", "radtan" if coeffs else "none", what="a distortion model name")
                       ).lower()
    if kalibr_model not in _KALIBR_DISTORTION:
        entry.fail(f"distortion_model {kalibr_model!r} is not supported; expected one of {sorted(_KALIBR_DISTORTION)}")
    intrinsics = _make_intrinsics(entry, (fx, fy, cx, cy, width, height), _KALIBR_DISTORTION[kalibr_model], coeffs,
                                  (f"{name}.intrinsics", f"{name}.distortion_coeffs"))
    counts = {"equidistant": (4,), "plumb_bob": (4, 5), "rational_polynomial": (8,), "none": (0,)}
    expected = counts[intrinsics.distortion_model]
    if len(intrinsics.distortion) not in expected:
        entry.fail(f"{len(intrinsics.distortion)} distortion_coeffs for {kalibr_model} (expected "
                   f"{' or '.join(map(str, expected))})")
    return replace(intrinsics, source=f"{top.source} [{name}]")


def _first(section: Section, keys: tuple[str, ...]) -> str | None:
    """The first of ``keys`` the section gives."""
    return next((key for key in keys if key in section), None)
