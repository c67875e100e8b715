"""The scene generator's own URDF forward kinematics: the XML read with ElementTree, chains in NumPy.

Independent of framechain's kinematics (:mod:`framechain.robot.kinematics`, which parses with
yourdfpy and chains quaternions): here every joint is a ``(T, 4, 4)`` matrix stack, ``origin @
motion``, multiplied from the root, so that the generated truth checks that code rather than repeats
it. Conventions are URDF's: ``rpy`` is fixed-axis roll, pitch, yaw (``R = Rz(y) Ry(p) Rx(r)``);
revolute and continuous joints rotate about ``axis``, prismatic joints slide along it; ``T_a_b``
maps points in frame b into frame a.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray

__all__ = ["UrdfChain", "UrdfJoint", "rpy_matrix"]


def rpy_matrix(rpy: npt.ArrayLike) -> FloatArray:
    """URDF's fixed-axis roll-pitch-yaw as a 3x3 matrix, ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    r, p, y = (float(v) for v in np.asarray(rpy, dtype=float))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def _axis_angle_stack(axis: FloatArray, angle: FloatArray) -> FloatArray:
    """Rodrigues' formula for one unit axis and ``(T,)`` angles: ``(T, 3, 3)``."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    out: FloatArray = np.eye(3) + s * k + (1.0 - c) * (k @ k)
    return out


@dataclass(frozen=True)
class UrdfJoint:
    """One URDF joint: its type, parent and child links, origin ``T_parent_jointframe`` and axis."""

    name: str
    kind: str
    parent: str
    child: str
    origin: FloatArray  # (4, 4)
    axis: FloatArray  # (3,) unit

    def local(self, position: FloatArray | None, n: int) -> FloatArray:
        """``T_parent_child`` at ``n`` frames (``position`` (n,) in SI units, None: the origin alone)."""
        out = np.broadcast_to(self.origin, (n, 4, 4)).copy()
        if position is None or self.kind == "fixed":
            return out
        motion = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        if self.kind == "prismatic":
            motion[:, :3, 3] = position[:, None] * self.axis
        else:
            motion[:, :3, :3] = _axis_angle_stack(self.axis, position)
        result: FloatArray = out @ motion
        return result


class UrdfChain:
    """The joints of one URDF, links optionally prefixed (``left_gripper_link``), FK as matrix stacks."""

    def __init__(self, path: str | Path, *, prefix: str = "") -> None:
        root = ET.parse(str(path)).getroot()
        self.prefix = prefix
        self.joints: dict[str, UrdfJoint] = {}
        for node in root.findall("joint"):
            origin = node.find("origin")
            xyz = _floats(origin.get("xyz") if origin is not None else None, 3)
            rpy = _floats(origin.get("rpy") if origin is not None else None, 3)
            axis_node = node.find("axis")
            axis = _floats(axis_node.get("xyz") if axis_node is not None else "1 0 0", 3)
            norm = float(np.linalg.norm(axis))
            transform = np.eye(4)
            transform[:3, :3] = rpy_matrix(rpy)
            transform[:3, 3] = xyz
            parent, child = node.find("parent"), node.find("child")
            if parent is None or child is None:
                raise ValueError(f"{path}: joint {node.get('name')!r} lacks a parent or child link")
            self.joints[str(node.get("name"))] = UrdfJoint(
                name=str(node.get("name")), kind=str(node.get("type")), parent=prefix + str(parent.get("link")),
                child=prefix + str(child.get("link")), origin=transform,
                axis=axis / norm if norm > 0 else np.array([1.0, 0.0, 0.0]),
            )
        self._by_child = {j.child: j for j in self.joints.values()}
        roots = {j.parent for j in self.joints.values()} - set(self._by_child)
        if len(roots) != 1:
            raise ValueError(f"{path}: expected one root link, found {sorted(roots)}")
        self.root: str = roots.pop()

    def path(self, link: str) -> list[UrdfJoint]:
        """The joints from the root to ``link``, root first."""
        out: list[UrdfJoint] = []
        current = link
        while current != self.root:
            if current not in self._by_child:
                raise KeyError(f"link {current!r} is not in the URDF (prefix {self.prefix!r})")
            joint = self._by_child[current]
            out.append(joint)
            current = joint.parent
        return out[::-1]

    def root_from_link(self, positions: Mapping[str, npt.ArrayLike], link: str) -> FloatArray:
        """``T_root_link`` at every frame, ``(T, 4, 4)``; ``positions`` maps joint name -> (T,) (SI)."""
        arrays = {k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in positions.items()}
        n = max((a.shape[0] for a in arrays.values()), default=1)
        out = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        for joint in self.path(link):
            out = out @ joint.local(arrays.get(joint.name), n)
        return out


def _floats(text: str | None, n: int) -> FloatArray:
    if text is None:
        return np.zeros(n)
    values = np.array([float(v) for v in text.split()])
    if values.shape != (n,):
        raise ValueError(f"expected {n} numbers, got {text!r}")
    return values
