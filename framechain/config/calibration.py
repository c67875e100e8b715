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
      rpy: [0.0, 0.0, 0.0]             # radians, fixed axes x-y-z as URDF; or quat_xyzw: [x, y, z, w]
      optical: false                   # required. true: the mount gives the optical frame (RDF)
                                       # directly. false: it gives a camera_link (FLU), and the
                                       # REP-103 rotation q_xyzw = (-0.5, 0.5, -0.5, 0.5) to the
                                       # optical frame is appended as <name>_link -> frame.
    video_key: observation.images.wrist  # optional dataset feature of this camera's images
    timing:                            # optional: when the camera's frames were taken
      timestamp_column: observation.images.wrist.timestamp  # per-frame camera time (s), or
      offset_s: 0.0                    # camera time = frame timestamp + offset_s
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

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from framechain.arrays import FloatArray
from framechain.geometry.conventions import OPTICAL_FROM_LINK_QUAT_XYZW
from framechain.timeline import CameraTable, FramechainError

#: camera_link (FLU) -> optical frame (RDF), REP-103: roll = -pi/2, yaw = -pi/2.

__all__ = [
    "OPTICAL_FROM_LINK_QUAT_XYZW",
    "CalibrationError",
    "CameraCalibration",
    "CameraTiming",
    "DepthSource",
    "Intrinsics",
    "Mount",
    "load_calibration",
    "read_intrinsics_file",
]


class CalibrationError(FramechainError):
    """A calibration file is unreadable, incomplete or inconsistent; names the file and the key."""

    def __init__(self, source: str, what: str) -> None:
        self.source = source
        self.what = what
        super().__init__(f"{source}: {what}")


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

    @property
    def K(self) -> FloatArray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class Mount:
    """``T_parent_frame`` of the camera: translation (m) and rotation ``quat_xyzw``.

    With ``optical`` False the mount gives a camera_link (FLU) and the optical frame hangs below it.
    """

    parent: str
    translation: tuple[float, float, float]
    quat_xyzw: tuple[float, float, float, float]
    optical: bool


@dataclass(frozen=True)
class CameraTiming:
    """When a camera's frames were taken relative to the dataset's per-frame timestamp."""

    timestamp_column: str | None = None
    offset_s: float = 0.0


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

    def mount_edges(self) -> list[tuple[str, str, FloatArray, FloatArray]]:
        """Static edges ``(parent, child, translation, quat_xyzw)`` from the mount link to the optical frame."""
        m = self.mount
        if m.optical:
            return [(m.parent, self.optical_frame, np.asarray(m.translation), np.asarray(m.quat_xyzw))]
        return [
            (m.parent, self.link_frame, np.asarray(m.translation), np.asarray(m.quat_xyzw)),
            (self.link_frame, self.optical_frame, np.zeros(3), np.asarray(OPTICAL_FROM_LINK_QUAT_XYZW)),
        ]


_TOP_KEYS = {"name", "frame", "intrinsics", "intrinsics_file", "mount", "video_key", "timing", "depth"}


def load_calibration(
    raw: str | Path | Mapping[str, Any], *, name: str | None = None, base_dir: str | Path | None = None
) -> CameraCalibration:
    """Read a camera calibration (a YAML file path, or an already-parsed mapping).

    ``name`` defaults to the file's ``name`` key, else the file stem. Relative paths in the
    calibration resolve against the file's directory (for a mapping: ``base_dir``).
    """
    if isinstance(raw, Mapping):
        source = f"calibration {name or raw.get('name', '?')}"
        data: Mapping[str, Any] = raw
        folder = Path(base_dir) if base_dir is not None else Path.cwd()
    else:
        path = Path(raw)
        if base_dir is not None and not path.is_absolute():
            path = Path(base_dir) / path
        source = str(path)
        data = _read_yaml(path)
        folder = path.parent
        if not isinstance(data, Mapping):
            raise CalibrationError(source, "expected a mapping at the top level")
        name = name or str(data.get("name") or path.stem)
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise CalibrationError(source, f"unknown keys {unknown}; known keys are {sorted(_TOP_KEYS)}")
    cam_name = str(name or data.get("name") or "")
    if not cam_name:
        raise CalibrationError(source, "the camera has no name")
    if "intrinsics" in data and "intrinsics_file" in data:
        raise CalibrationError(source, "give either intrinsics or intrinsics_file, not both")
    if "intrinsics" in data:
        intrinsics = _inline_intrinsics(data["intrinsics"], source)
    elif "intrinsics_file" in data:
        ipath = Path(str(data["intrinsics_file"]))
        intrinsics = read_intrinsics_file(ipath if ipath.is_absolute() else folder / ipath)
    else:
        raise CalibrationError(
            source, "no intrinsics: give intrinsics: {fx, fy, cx, cy, width, height} or intrinsics_file"
        )
    if "mount" not in data:
        raise CalibrationError(source, "no mount: give mount: {parent, xyz, rpy | quat_xyzw, optical}")
    mount = _mount(data["mount"], source)
    timing_raw = data.get("timing") or {}
    _check(timing_raw, {"timestamp_column", "offset_s"}, source, "timing")
    offset = timing_raw.get("offset_s", 0.0)
    if not isinstance(offset, int | float) or not math.isfinite(offset):
        raise CalibrationError(source, f"timing.offset_s must be a number of seconds, got {offset!r}")
    column = timing_raw.get("timestamp_column")
    timing = CameraTiming(None if column is None else str(column), float(offset))
    depth = None
    if data.get("depth") is not None:
        depth_raw = data["depth"]
        _check(depth_raw, {"feature", "scale_m"}, source, "depth")
        if "feature" not in depth_raw:
            raise CalibrationError(source, "depth needs feature: the dataset's depth image feature")
        scale = depth_raw.get("scale_m", 1.0)
        if not isinstance(scale, int | float) or not scale > 0:
            raise CalibrationError(source, f"depth.scale_m must be a positive number, got {scale!r}")
        depth = DepthSource(str(depth_raw["feature"]), float(scale))
    video_key = data.get("video_key")
    return CameraCalibration(
        name=cam_name, intrinsics=intrinsics, mount=mount, frame=str(data.get("frame") or "").lstrip("/"),
        video_key=None if video_key is None else str(video_key), timing=timing, depth=depth, source=source,
    )


def _read_yaml(path: Path) -> Any:
    try:
        text = path.read_text()
    except OSError as err:
        raise CalibrationError(str(path), f"cannot read calibration ({err.strerror})") from err
    try:
        return yaml.load(_strip_opencv_header(text), Loader=_OpenCVLoader)  # a SafeLoader subclass
    except yaml.YAMLError as err:
        raise CalibrationError(str(path), f"not valid YAML ({err})") from err


def _check(raw: Any, known: set[str], source: str, where: str) -> None:
    if not isinstance(raw, Mapping):
        raise CalibrationError(source, f"{where} must be a mapping, got {type(raw).__name__}")
    unknown = sorted(set(raw) - known)
    if unknown:
        raise CalibrationError(source, f"{where}: unknown keys {unknown}; known keys are {sorted(known)}")


def _number(raw: Mapping[str, Any], key: str, source: str, where: str) -> float:
    if key not in raw:
        raise CalibrationError(source, f"{where}: missing {key}")
    value = raw[key]
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise CalibrationError(source, f"{where}.{key} must be a finite number, got {value!r}")
    return float(value)


def _vector(raw: Any, n: int, source: str, what: str) -> tuple[float, ...]:
    try:
        arr = np.asarray(raw, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise CalibrationError(source, f"{what} must be a list of {n} numbers, got {raw!r}") from None
    if arr.shape != (n,) or not np.isfinite(arr).all():
        raise CalibrationError(source, f"{what} must be {n} finite numbers, got {raw!r}")
    return tuple(float(x) for x in arr)


def _inline_intrinsics(raw: Any, source: str) -> Intrinsics:
    _check(raw, {"fx", "fy", "cx", "cy", "width", "height", "distortion_model", "distortion"}, source, "intrinsics")
    dist = raw.get("distortion") or []
    return _make_intrinsics(
        _number(raw, "fx", source, "intrinsics"), _number(raw, "fy", source, "intrinsics"),
        _number(raw, "cx", source, "intrinsics"), _number(raw, "cy", source, "intrinsics"),
        _number(raw, "width", source, "intrinsics"), _number(raw, "height", source, "intrinsics"),
        str(raw.get("distortion_model") or ("plumb_bob" if dist else "none")), dist, source,
    )


def _make_intrinsics(
    fx: float, fy: float, cx: float, cy: float, width: float, height: float, model: str, dist: Any, source: str
) -> Intrinsics:
    if not (fx > 0 and fy > 0):
        raise CalibrationError(source, f"focal lengths fx={fx} fy={fy} must be positive")
    if not (width >= 1 and height >= 1 and float(width).is_integer() and float(height).is_integer()):
        raise CalibrationError(source, f"image size {width}x{height} must be positive integers")
    coeffs = np.asarray(dist if dist is not None else [], dtype=float).reshape(-1)
    if coeffs.size > 14 or not np.isfinite(coeffs).all():
        raise CalibrationError(source, f"distortion must be at most 14 finite numbers, got {coeffs.size}")
    return Intrinsics(fx, fy, cx, cy, int(width), int(height), model, tuple(float(c) for c in coeffs), source)


def _mount(raw: Any, source: str) -> Mount:
    _check(raw, {"parent", "xyz", "rpy", "quat_xyzw", "optical"}, source, "mount")
    if "parent" not in raw:
        raise CalibrationError(source, "mount: missing parent (the link the camera is mounted on)")
    if "optical" not in raw or not isinstance(raw["optical"], bool):
        raise CalibrationError(
            source,
            "mount.optical must be stated, true or false: true if the mount gives the optical frame "
            "(x right, y down, z forward), false if it gives a camera_link (x forward, y left, z up)",
        )
    xyz = _vector(raw.get("xyz", [0.0, 0.0, 0.0]), 3, source, "mount.xyz")
    if "rpy" in raw and "quat_xyzw" in raw:
        raise CalibrationError(source, "mount: give either rpy or quat_xyzw, not both")
    if "quat_xyzw" in raw:
        q = np.asarray(_vector(raw["quat_xyzw"], 4, source, "mount.quat_xyzw"))
        norm = float(np.linalg.norm(q))
        if abs(norm - 1.0) > 1e-3:
            raise CalibrationError(source, f"mount.quat_xyzw has norm {norm:.6g}, not 1 (order is x, y, z, w)")
        q = q / norm
    else:
        rpy = _vector(raw.get("rpy", [0.0, 0.0, 0.0]), 3, source, "mount.rpy")
        q = Rotation.from_euler("xyz", rpy).as_quat()  # URDF rpy: fixed axes, roll about x first
    quat = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
    return Mount(str(raw["parent"]).lstrip("/"), (xyz[0], xyz[1], xyz[2]), quat, bool(raw["optical"]))


# ------------------------------------------------------------------------------ intrinsics files


class _OpenCVLoader(yaml.SafeLoader):
    """SafeLoader that understands OpenCV's ``!!opencv-matrix`` tag."""


def _opencv_matrix(loader: yaml.SafeLoader, node: yaml.Node) -> list[list[float]]:
    assert isinstance(node, yaml.MappingNode)
    m = loader.construct_mapping(node, deep=True)
    rows, cols = int(m["rows"]), int(m["cols"])
    data = np.asarray(m["data"], dtype=float).reshape(rows, cols)
    out: list[list[float]] = data.tolist()
    return out


_OpenCVLoader.add_constructor("tag:yaml.org,2002:opencv-matrix", _opencv_matrix)


def _strip_opencv_header(text: str) -> str:
    """OpenCV writes ``%YAML:1.0`` (not valid YAML 1.1) on its first line: drop it."""
    lines = text.splitlines()
    if lines and lines[0].startswith("%YAML:"):
        lines = lines[1:]
        if lines and lines[0].strip() == "---":
            lines = lines[1:]
    return "\n".join(lines)


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
    raw = _read_yaml(p)
    if not isinstance(raw, Mapping):
        raise CalibrationError(source, "expected a mapping of calibration keys")
    if _is_kalibr(raw):
        return _kalibr_camera(raw, camera, source)
    named = raw.get("camera_name")
    if camera is not None and named is not None and str(named) != camera:
        raise CalibrationError(source, f"camera {camera!r} is not in the file; it holds camera_name {named!r}")
    K = _first(raw, ("camera_matrix", "K", "cameraMatrix", "camera_matrix_left"))
    if K is None:
        raise CalibrationError(source, "no camera matrix (camera_matrix, K or cameraMatrix)")
    if isinstance(K, Mapping):  # ROS: {rows, cols, data}
        if "data" not in K:
            raise CalibrationError(source, "camera_matrix has no data")
        K = K["data"]
    kmat = np.asarray(_vector(K, 9, source, "camera_matrix"), dtype=float).reshape(3, 3)
    dist = _first(raw, ("distortion_coefficients", "D", "dist_coeffs", "distCoeffs", "distortion"))
    if isinstance(dist, Mapping):
        dist = dist.get("data", [])
    coeffs = np.asarray(dist if dist is not None else [], dtype=float).reshape(-1)
    width = _first(raw, ("image_width", "width", "imageWidth"))
    height = _first(raw, ("image_height", "height", "imageHeight"))
    if width is None or height is None:
        size = _first(raw, ("image_size", "imageSize"))
        if size is not None:
            width, height = np.asarray(size, dtype=float).reshape(-1)[:2]
        else:
            raise CalibrationError(source, "no image size (image_width/image_height or width/height)")
    model = str(raw.get("distortion_model") or ("plumb_bob" if coeffs.size in (4, 5) else
                                                "rational_polynomial" if coeffs.size == 8 else
                                                "none" if coeffs.size == 0 else "plumb_bob"))
    if abs(kmat[0, 1]) > 1e-9 or abs(kmat[2, 2] - 1.0) > 1e-9:
        raise CalibrationError(source, f"camera matrix {kmat.tolist()} is not a pinhole K (skew 0, K[2,2] = 1)")
    return _make_intrinsics(
        float(kmat[0, 0]), float(kmat[1, 1]), float(kmat[0, 2]), float(kmat[1, 2]),
        float(width), float(height), model, coeffs, source,
    )


#: Kalibr distortion names -> ROS names (radtan is plumb_bob without k3).
_KALIBR_DISTORTION = {"radtan": "plumb_bob", "plumb_bob": "plumb_bob", "equidistant": "equidistant",
                      "fisheye": "equidistant", "rational_polynomial": "rational_polynomial", "none": "none"}


def _is_kalibr(raw: Mapping[str, Any]) -> bool:
    """A camchain: camera names mapping to entries with a Kalibr ``intrinsics`` list."""
    return any(isinstance(v, Mapping) and isinstance(v.get("intrinsics"), list) for v in raw.values())


def kalibr_cameras(path: str | Path) -> list[str]:
    """The camera names of a Kalibr camchain file (empty for other calibration files)."""
    raw = _read_yaml(Path(path))
    if not isinstance(raw, Mapping) or not _is_kalibr(raw):
        return []
    return [str(k) for k, v in raw.items() if isinstance(v, Mapping)]


def _kalibr_camera(raw: Mapping[str, Any], camera: str | None, source: str) -> Intrinsics:
    entries = {str(k): v for k, v in raw.items() if isinstance(v, Mapping)}
    if camera is None:
        if len(entries) != 1:
            raise CalibrationError(source, f"{len(entries)} cameras ({', '.join(entries)}); pick one with "
                                   "camera: NAME (or its rostopic or tagtopic)")
        name = next(iter(entries))
    elif camera in entries:
        name = camera
    else:
        by_topic = [k for k, v in entries.items() if camera in (v.get("rostopic"), v.get("tagtopic"))]
        if not by_topic:
            listed = ", ".join(f"{k} ({v.get('rostopic', 'no rostopic')})" for k, v in entries.items())
            raise CalibrationError(source, f"camera {camera!r} is not in the file; its cameras are {listed}")
        name = by_topic[0]
    entry = entries[name]
    where = name
    model = str(entry.get("camera_model", "pinhole"))
    if model != "pinhole":
        raise CalibrationError(source, f"{where}: camera_model {model!r} is not supported (pinhole only)")
    fx, fy, cx, cy = _vector(entry.get("intrinsics"), 4, source, f"{where}.intrinsics [fx, fy, cx, cy]")
    if "resolution" not in entry:
        raise CalibrationError(source, f"{where}: no resolution [width, height]")
    width, height = _vector(entry["resolution"], 2, source, f"{where}.resolution [width, height]")
    coeffs = entry.get("distortion_coeffs") or []
    kalibr_model = str(entry.get("distortion_model") or ("radtan" if coeffs else "none")).lower()
    if kalibr_model not in _KALIBR_DISTORTION:
        raise CalibrationError(source, f"{where}: distortion_model {kalibr_model!r} is not supported; expected one "
                               f"of {sorted(_KALIBR_DISTORTION)}")
    intrinsics = _make_intrinsics(fx, fy, cx, cy, width, height, _KALIBR_DISTORTION[kalibr_model], coeffs,
                                  f"{source} [{name}]")
    counts = {"equidistant": (4,), "plumb_bob": (4, 5), "rational_polynomial": (8,), "none": (0,)}
    expected = counts[intrinsics.distortion_model]
    if len(intrinsics.distortion) not in expected:
        raise CalibrationError(source, f"{where}: {len(intrinsics.distortion)} distortion_coeffs for "
                               f"{kalibr_model} (expected {' or '.join(map(str, expected))})")
    return intrinsics


def _first(raw: Mapping[str, Any], keys: tuple[str, ...]) -> Any:
    for key in keys:
        if key in raw and raw[key] is not None:
            return raw[key]
    return None
