"""What a chain file adds to a log: camera models from calibration files, static edges from
``mounts:`` and from the fixed joints of a URDF (the chain's ``urdf:`` file, or the log's
``/robot_description``).

Precedence, decided once here and documented in
docs/cli.md#calibration-mounts-and-poses-from-outside-the-log:

- a calibration file the chain names is used for its camera frame; the log's CameraInfo for that
  frame is dropped, with a note giving both values when they differ;
- a mount (and a fixed joint of the chain's URDF) replaces the log's edge with the same child
  (or the same edge reversed), with a note giving both values: the user said so explicitly; a
  mount whose child moves under another parent in the log is an error (it would cut the tree);
- a fixed joint of the log's own ``/robot_description`` only fills in edges the log lacks.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from framechain.config.calibration import CalibrationError, Intrinsics, read_intrinsics_file
from framechain.config.chain import ChainConfig
from framechain.config.errors import ChainConfigError
from framechain.config.mount import Mount
from framechain.geometry.rotations import invert, quat_angle_between, quat_from_matrix
from framechain.robot.urdf import JointType, RobotModelError, UrdfJoints, read_urdf, read_urdf_text
from framechain.timeline import CameraTable, TransformTable


class FileCamera(NamedTuple):
    """A camera model read from a calibration file, for the optical frame ``frame``."""

    frame: str
    intrinsics: Intrinsics
    source: str  # e.g. "cameras.yaml [cam0]"


class ChainAdditions(NamedTuple):
    """Everything a chain file adds to the log it is read with."""

    cameras: list[FileCamera]
    edges: list[Mount]  # explicit (mounts, then the chain's URDF): they win over the log
    notes: list[str]


def chain_additions(chain: ChainConfig | None) -> ChainAdditions:
    """Read the calibration files and URDF the chain names; raise a one-line error if one is unusable.

    The notes say what the chain's own values look unusual for (plausible, but worth a look)."""
    if chain is None:
        return ChainAdditions([], [], [])
    notes: list[str] = list(chain.notes)
    cameras: list[FileCamera] = []
    for entry in chain.calibration_sources():
        path = chain.resolve(entry.file)
        intrinsics = read_intrinsics_file(path, camera=entry.camera)
        notes.extend(intrinsics.notes)
        which = intrinsics.source[len(str(path)):]  # " [cam0]" for a Kalibr camera, else ""
        cameras.append(FileCamera(entry.frame or chain.frames.camera, intrinsics, path.name + which))
    seen: dict[str, str] = {}
    for cam in cameras:
        if cam.frame in seen:
            raise CalibrationError(f"{chain.origin} calibration",
                                   f"frame {cam.frame!r} gets two calibrations ({seen[cam.frame]}, {cam.source})")
        seen[cam.frame] = cam.source
    edges = [replace(m, source=f"{chain.origin} mounts[{i}]") for i, m in enumerate(chain.mounts)]
    children: dict[str, str] = {}
    for e in edges:
        if e.child in children:
            raise ChainConfigError(e.source, f"frame {e.child!r} is already the child of {children[e.child]}")
        children[e.child] = e.source
    if chain.urdf:
        path = chain.resolve(chain.urdf)
        try:
            urdf = read_urdf(path)
        except RobotModelError as err:
            raise ChainConfigError(err.source, err.what) from err
        for e in urdf_fixed_edges(urdf, path.name):
            if e.child in children:
                notes.append(f"{path.name}: fixed joint {e.parent} -> {e.child} not used; {children[e.child]} "
                             "gives that frame")
            else:
                edges.append(e)
    return ChainAdditions(cameras, edges, notes)


def urdf_fixed_edges(urdf: UrdfJoints, source: str) -> list[Mount]:
    """The fixed joints of a URDF as mounts ``T_parent_link_child_link`` (the joint's origin)."""
    out: list[Mount] = []
    for joint in urdf.joints:
        if joint.type is not JointType.FIXED:
            continue
        t = joint.origin[:3, 3]
        q = quat_from_matrix(joint.origin[:3, :3])
        out.append(Mount(joint.parent.lstrip("/"), joint.child.lstrip("/"), (float(t[0]), float(t[1]), float(t[2])),
                         (float(q[0]), float(q[1]), float(q[2]), float(q[3])), source=source))
    return out


def log_urdf_edges(descriptions: dict[str, str]) -> tuple[list[Mount], list[str]]:
    """Fixed joints of the robot descriptions a log carries (topic -> URDF text); a bad one is a note."""
    edges: list[Mount] = []
    notes: list[str] = []
    for topic, text in sorted(descriptions.items()):
        try:
            edges.extend(urdf_fixed_edges(read_urdf_text(text, topic), topic))
        except RobotModelError as err:
            notes.append(f"topic {topic}: robot description not used ({err.what})")
    return edges, notes


def _fmt(values: npt.ArrayLike) -> str:
    return "[" + ", ".join(f"{float(v):.6g}" for v in np.asarray(values).reshape(-1)) + "]"


def _edge_text(parent: str, child: str, xyz: npt.ArrayLike, quat: npt.ArrayLike) -> str:
    return f"{parent} -> {child} xyz {_fmt(xyz)} quat_xyzw {_fmt(quat)}"


def merge_static_edges(
    table: TransformTable, explicit: list[Mount], described: list[Mount]
) -> tuple[TransformTable, list[str]]:
    """The log's edges plus the chain's (``explicit``: they replace the log's edge with the same child,
    or the same edge reversed) and the log's URDF joints (``described``: only where the log has none)."""
    notes: list[str] = []
    keep = np.ones(len(table), dtype=bool)
    for e in explicit:
        hit = ((table.child == e.child) | ((table.child == e.parent) & (table.parent == e.child))) & keep
        if hit.any():
            notes.append(_replacement_note(table, e, hit))
            keep &= ~hit
    parent_of = dict(zip(table.child[keep].tolist(), table.parent[keep].tolist(), strict=True))
    parent_of.update({e.child: e.parent for e in explicit})
    filled = _fill_in(described, parent_of, notes)
    for source in sorted({e.source for e in filled}):
        mine = [e.child for e in filled if e.source == source]
        notes.append(f"{source}: {len(mine)} fixed joint{'s' if len(mine) != 1 else ''} of the robot description "
                     f"added as static edges the log lacks ({', '.join(mine[:6])}{', ...' if len(mine) > 6 else ''})")
    added = [*explicit, *filled]
    if not added:
        return table.take(keep), notes
    n = len(added)
    extra = TransformTable.from_rows(
        [e.parent for e in added], [e.child for e in added], np.zeros(n, dtype=np.int64),
        [e.xyz for e in added], [e.quat_xyzw for e in added], log_time_ns=np.zeros(n, dtype=np.int64),
        is_static=True, source=[e.source for e in added],
    )
    return TransformTable.concat([extra, table.take(keep)]), notes


def _replacement_note(table: TransformTable, e: Mount, hit: npt.NDArray[np.bool_]) -> str:
    """What the log's rows ``hit`` (the mount's edge, or the same edge reversed) held, and how far the mount that
    replaces them differs; a mount whose child moves under another parent in the log is an error."""
    rows = np.flatnonzero(hit)
    first = int(rows[0])
    moving = hit & ~table.is_static & (table.parent != e.parent)
    if moving.any():  # replacing a moving parent would cut the tree, never what a mount means
        r = int(np.flatnonzero(moving)[0])
        raise ChainConfigError(
            e.source, f"frame {e.child!r} already has the moving parent {str(table.parent[r])!r} in the log "
            f"({table.source[r]}); a frame has one parent: give the mount the other way round "
            f"(parent: {e.child}, child: {e.parent}, the inverse transform)")
    t, q = table.translation[first], table.quat_xyzw[first]
    if table.child[first] != e.child:  # the edge reversed: compare like with like, T_parent_child both
        t, q = invert(t, q)
    moved_mm = float(np.linalg.norm(np.asarray(e.xyz) - t)) * 1e3
    turned_deg = float(np.degrees(quat_angle_between(q, np.asarray(e.quat_xyzw))))
    how = "static" if table.is_static[rows].all() else f"dynamic, {rows.size} samples, the first shown"
    logged = _edge_text(str(table.parent[first]), str(table.child[first]), table.translation[first],
                        table.quat_xyzw[first])
    return (f"{e.source}: {_edge_text(e.parent, e.child, e.xyz, e.quat_xyzw)} is used instead of the log's {logged} "
            f"({how}; on {', '.join(sorted(set(table.source[rows].tolist())))}): they differ by {moved_mm:.1f} mm "
            f"and {turned_deg:.2f} deg")


def _fill_in(described: list[Mount], parent_of: dict[str, str], notes: list[str]) -> list[Mount]:
    """The fixed joints of a log's robot description for frames without a parent (``parent_of``, updated), none
    that would close a loop (a note says so)."""
    filled: list[Mount] = []
    for e in described:
        if e.child in parent_of:
            continue
        frame: str | None = e.parent
        seen = set()
        while frame is not None and frame not in seen and frame != e.child:
            seen.add(frame)
            frame = parent_of.get(frame)
        if frame == e.child:
            notes.append(f"{e.source}: fixed joint {e.parent} -> {e.child} not added (it would close a loop)")
            continue
        filled.append(e)
        parent_of[e.child] = e.parent
    return filled


def merge_file_cameras(table: CameraTable, cameras: list[FileCamera]) -> tuple[CameraTable, list[str]]:
    """The calibration files' camera models (timeless: stamp 0) in place of the log's for their frames."""
    notes: list[str] = []
    keep = np.ones(len(table), dtype=bool)
    rows: list[CameraTable] = []
    for cam in cameras:
        i = cam.intrinsics
        row = CameraTable.from_intrinsics(
            cam.frame, fx=i.fx, fy=i.fy, cx=i.cx, cy=i.cy, width=i.width, height=i.height,
            distortion_model=i.distortion_model, distortion=i.distortion, source=cam.source,
        )
        rows.append(row)
        mine = np.flatnonzero(table.frame == cam.frame)
        if mine.size == 0:
            continue
        topics = ", ".join(sorted(set(table.source[mine].tolist())))
        differences = [d for r in mine.tolist() if (d := _camera_differences(row, table, int(r)))]
        if differences:
            notes.append(f"camera {cam.frame}: the calibration from {cam.source} is used (the chain names it), not "
                         f"the log's CameraInfo on {topics}, which differs: {differences[0]}")
        else:
            notes.append(f"camera {cam.frame}: the calibration from {cam.source} agrees with the log's CameraInfo on "
                         f"{topics}; the file's is used")
        keep[mine] = False
    return CameraTable.concat([*rows, table.take(keep)]), notes


def _camera_differences(file_row: CameraTable, log: CameraTable, r: int) -> str:
    """What differs between the file's camera model and the log's row ``r`` ("" if nothing)."""
    parts: list[str] = []
    fk, lk = file_row.K[0], log.K[r]
    names = (("fx", 0, 0), ("fy", 1, 1), ("cx", 0, 2), ("cy", 1, 2))
    for name, a, b in names:
        if not math.isclose(float(fk[a, b]), float(lk[a, b]), rel_tol=1e-6, abs_tol=1e-9):
            parts.append(f"{name} {float(fk[a, b]):.6g} (file) vs {float(lk[a, b]):.6g} (log)")
    if (file_row.width[0], file_row.height[0]) != (log.width[r], log.height[r]):
        parts.append(f"size {file_row.width[0]}x{file_row.height[0]} (file) vs {log.width[r]}x{log.height[r]} (log)")
    fd, ld = file_row.distortion[0], log.distortion[r]
    if str(file_row.distortion_model[0]) != str(log.distortion_model[r]) or not np.allclose(fd, ld, rtol=1e-6,
                                                                                              atol=1e-9):
        parts.append(f"distortion {file_row.distortion_model[0]} {_fmt(fd[: int(file_row.n_distortion[0])])} (file) "
                     f"vs {log.distortion_model[r]} {_fmt(ld[: int(log.n_distortion[r])])} (log)")
    return "; ".join(parts)
