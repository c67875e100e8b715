"""A URDF's joints as framechain keeps them, parsed by yourdfpy once per URDF text.

yourdfpy imports trimesh, which imports scipy.spatial, scipy.optimize and networkx: 0.4 s of a command
that reads one episode, and 0.1 s more of the interpreter's teardown at its exit, against a few
milliseconds to parse an arm's URDF. So the joints parsed are kept in a cache, one JSON file per URDF
text (named by the SHA-256 of the text, this cache's format and yourdfpy's version), and a later
command given the same text reads them back without importing yourdfpy. The numbers round-trip
exactly (JSON keeps a float's shortest repr). Only a parse that succeeded is kept; a cache file that
cannot be read is parsed again, and one that cannot be written is not kept.

The cache lives in ``$FRAMECHAIN_CACHE_DIR/urdf`` (the variable set empty: nothing cached), else
``$XDG_CACHE_HOME/framechain/urdf``, else ``~/.cache/framechain/urdf``.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import os
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from framechain.arrays import FloatArray
from framechain.errors import FramechainError
from framechain.files import write_atomically

__all__ = ["CACHE_ENV", "Joint", "JointType", "Mimic", "RobotModelError", "UrdfJoints", "cache_dir", "read_urdf",
           "read_urdf_text"]


class RobotModelError(FramechainError):
    """The URDF cannot be used (unreadable, not a tree, unsupported joint) or a query is wrong."""

    def __init__(self, source: str, what: str) -> None:
        self.source = source
        self.what = what
        super().__init__(f"{source}: {what}" if source else what)


class JointType(StrEnum):
    """URDF joint types framechain can move (floating and planar are refused)."""

    REVOLUTE = "revolute"
    CONTINUOUS = "continuous"
    PRISMATIC = "prismatic"
    FIXED = "fixed"


@dataclass(frozen=True)
class Mimic:
    """``q = multiplier * q[joint] + offset``."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class Joint:
    """One URDF joint: ``T_parent_child(q) = origin @ motion(axis, q)``.

    ``origin`` is 4x4 (``T_parent_jointframe``); ``axis`` a unit 3-vector in the joint frame;
    limits in radians or metres (None where the URDF gives none).
    """

    name: str
    type: JointType
    parent: str
    child: str
    origin: FloatArray
    axis: FloatArray
    lower: float | None = None
    upper: float | None = None
    mimic: Mimic | None = None

    @property
    def moves(self) -> bool:
        return self.type is not JointType.FIXED


class UrdfJoints(NamedTuple):
    """The joints of a URDF as parsed (not yet checked to be a tree), and those of types framechain
    cannot move (floating, planar) by name and type."""

    source: str
    name: str
    joints: list[Joint]
    unsupported: list[tuple[str, str]]


def read_urdf(path: Path) -> UrdfJoints:
    """The joints of a URDF file, parsed by yourdfpy (meshes not loaded), or read from the cache of an earlier parse
    of the same text."""
    if not path.is_file():
        raise RobotModelError(str(path), "URDF file not found")
    try:
        data = path.read_bytes()
    except OSError as err:
        raise RobotModelError(str(path), f"cannot read the URDF ({err.strerror or err})") from err
    return _cached(data, str(path), lambda: _parse_urdf(str(path), str(path)))


def read_urdf_text(text: str, source: str) -> UrdfJoints:
    """The joints of URDF text (a log's ``/robot_description``); ``source`` names it in messages."""
    data = text.encode()
    return _cached(data, source, lambda: _parse_urdf(io.BytesIO(data), source))


def _parse_urdf(file: str | io.BytesIO, source: str) -> UrdfJoints:
    import yourdfpy

    quiet = logging.getLogger("yourdfpy")
    level = quiet.level
    quiet.setLevel(logging.CRITICAL + 1)  # yourdfpy logs parse errors on stderr before raising: one line is ours
    try:
        urdf = yourdfpy.URDF.load(file, build_scene_graph=False, load_meshes=False, build_collision_scene_graph=False,
                                  load_collision_meshes=False)
    except Exception as err:  # yourdfpy raises lxml, ValueError, KeyError... on bad files
        raise RobotModelError(source, f"cannot parse URDF ({type(err).__name__}: {' '.join(str(err).split())})"
                              ) from err
    finally:
        quiet.setLevel(level)
    joints: list[Joint] = []
    unsupported: list[tuple[str, str]] = []
    for raw in urdf.robot.joints:
        origin = np.eye(4) if raw.origin is None else np.asarray(raw.origin, dtype=float)
        if not np.isfinite(origin).all():
            raise RobotModelError(source, f"joint {raw.name!r}: its origin is not finite")
        try:
            jtype = JointType(raw.type)
        except ValueError:
            unsupported.append((str(raw.name), str(raw.type)))
            continue
        joints.append(_joint(raw, jtype, origin, source))
    return UrdfJoints(source, str(urdf.robot.name or ""), joints, unsupported)


def _joint(raw: Any, jtype: JointType, origin: FloatArray, source: str) -> Joint:
    """A yourdfpy joint as a :class:`Joint` (axis normalised, limits and mimic read)."""
    axis = np.array([1.0, 0.0, 0.0]) if raw.axis is None else np.asarray(raw.axis, dtype=float)
    if jtype is not JointType.FIXED:
        norm = float(np.linalg.norm(axis))
        if not np.isfinite(norm) or norm < 1e-12:
            raise RobotModelError(source, f"joint {raw.name!r} has a zero axis")
        axis = axis / norm
    lower = upper = None
    if raw.limit is not None and jtype is not JointType.CONTINUOUS:
        lower = None if raw.limit.lower is None else float(raw.limit.lower)
        upper = None if raw.limit.upper is None else float(raw.limit.upper)
    mimic = None
    if raw.mimic is not None:
        mimic = Mimic(str(raw.mimic.joint), 1.0 if raw.mimic.multiplier is None else float(raw.mimic.multiplier),
                      0.0 if raw.mimic.offset is None else float(raw.mimic.offset))
    return Joint(str(raw.name), jtype, str(raw.parent), str(raw.child), origin, axis, lower, upper, mimic)


#: The variable naming framechain's cache directory (set empty: nothing cached).
CACHE_ENV = "FRAMECHAIN_CACHE_DIR"
#: Bumped whenever what a cache file holds changes.
_CACHE_FORMAT = 1


def cache_dir() -> Path | None:
    """framechain's cache directory (:data:`CACHE_ENV`, else the XDG cache home's ``framechain``); None: no cache."""
    given = os.environ.get(CACHE_ENV)
    if given is not None:
        return Path(given) if given.strip() else None
    home = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(home) / "framechain"


def _cached(data: bytes, source: str, parse: Callable[[], UrdfJoints]) -> UrdfJoints:
    """The joints of URDF text ``data``: from the cache when an earlier parse of the same text left them, else
    ``parse()``d and kept."""
    root = cache_dir()
    if root is None:
        return parse()
    from importlib.metadata import PackageNotFoundError, version

    try:
        parser = version("yourdfpy")
    except PackageNotFoundError:
        parser = ""
    key = hashlib.sha256(b"%d|%s|" % (_CACHE_FORMAT, parser.encode()) + data).hexdigest()
    path = root / "urdf" / f"{key}.json"
    try:
        return _joints_of(json.loads(path.read_text()), source)
    except (OSError, ValueError, KeyError, TypeError, IndexError):
        pass  # not cached yet, or unreadable: parsed again
    parsed = parse()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        # Whole or not at all: a command reading it at the same time sees all of it or none.
        write_atomically(path, lambda tmp: tmp.write_text(json.dumps(_json_of(parsed))))
    except OSError:
        pass  # a read-only home: nothing kept
    return parsed


def _json_of(urdf: UrdfJoints) -> dict[str, Any]:
    return {"name": urdf.name, "unsupported": [list(u) for u in urdf.unsupported], "joints": [
        {"name": j.name, "type": j.type.value, "parent": j.parent, "child": j.child,
         "origin": j.origin.reshape(-1).tolist(), "axis": j.axis.tolist(), "lower": j.lower, "upper": j.upper,
         "mimic": None if j.mimic is None else [j.mimic.joint, j.mimic.multiplier, j.mimic.offset]}
        for j in urdf.joints]}


def _joints_of(cached: dict[str, Any], source: str) -> UrdfJoints:
    joints = [Joint(str(j["name"]), JointType(j["type"]), str(j["parent"]), str(j["child"]),
                    np.array(j["origin"], dtype=float).reshape(4, 4), np.array(j["axis"], dtype=float),
                    _number(j["lower"]), _number(j["upper"]),
                    None if j["mimic"] is None else Mimic(str(j["mimic"][0]), float(j["mimic"][1]),
                                                          float(j["mimic"][2])))
              for j in cached["joints"]]
    return UrdfJoints(source, str(cached["name"]), joints, [(str(a), str(b)) for a, b in cached["unsupported"]])


def _number(value: Any) -> float | None:
    return None if value is None else float(value)
