"""A robot model from a URDF and batched forward kinematics over whole episodes.

yourdfpy parses the URDF (meshes are never loaded); everything after parsing is NumPy. Forward
kinematics runs on whole arrays of joint positions, one ``(T, 4, 4)`` stack per link, never one
Python call per frame:

- :meth:`RobotModel.joint_poses` gives each joint's local ``T_parent_child`` at every frame
  (origin @ motion) as translations and quaternions, the rows a Timeline stores;
  :meth:`RobotModel.joint_transforms` gives the same as ``(T, 4, 4)`` stacks;
- :meth:`RobotModel.link_poses` chains them from the root, ``T_root_link`` per link, and
  :meth:`RobotModel.fk_path` chains one path in cache-sized blocks (the benchmarked hot path).

Chaining does not multiply ``(T, 4, 4)`` stacks: NumPy's batched 4x4 matmul costs about 180 ns a
product, and BLAS products of tall ``(3T, 3)`` stacks stall when the cores are shared. Poses are
kept as structure-of-arrays, a unit quaternion (four ``(T,)`` arrays) and a translation (three),
and a revolute joint's local rotation is ``q0 (x) (a sin(q/2), cos(q/2)) = cos(q/2) q0 +
sin(q/2) (q0 (x) a)`` with constant ``q0`` (the origin's rotation) and ``q0 (x) a``; so one joint
costs about seventy element-wise passes over the frames and no Python per frame. Matrices are
built once at the end. A 6-joint arm chains at about two million configurations a second on a
busy 2-core machine, against about a thousand for yourdfpy one at a time
(``benchmarks/bench_fk.py``).

Conventions: ``T_a_b`` maps points in frame b into frame a; joint positions are SI (radians for
revolute and continuous joints, metres for prismatic ones); a mimic joint follows
``q = multiplier * q_source + offset``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray
from framechain.geometry.rotations import QuatLike, VecLike, compose, homogeneous, quat_from_matrix, quat_multiply
from framechain.robot.urdf import Joint, JointType, RobotModelError, read_urdf

#: Frames per block in :meth:`RobotModel.fk_path`.
FK_BLOCK = 8192

__all__ = ["RobotModel"]


@dataclass(frozen=True)
class _Step:
    """A joint's constants for the chained product (see the module docstring)."""

    joint: Joint
    q0: tuple[float, float, float, float]  # rotation of the origin, xyzw
    t0: tuple[float, float, float]  # translation of the origin
    qa: tuple[float, float, float, float]  # revolute: q0 (x) (axis, 0); else zeros
    d: tuple[float, float, float]  # prismatic: R0 @ axis, the direction of travel in the parent


Quat = QuatLike
Vec = VecLike


class RobotModel:
    """The kinematic tree of one URDF: joints by name, links, the root, batched FK.

    Build with :meth:`from_urdf`. Joint positions are given as a mapping ``joint -> (T,)`` (SI
    units) or a ``(T, J)`` array ordered as :attr:`actuated`; mimic joints are derived.
    """

    def __init__(self, joints: Sequence[Joint], *, source: str = "", name: str = "") -> None:
        self.source = source
        self.name = name
        self.joints: dict[str, Joint] = {}
        self._by_child: dict[str, Joint] = {}
        for joint in joints:
            if joint.name in self.joints:
                raise RobotModelError(source, f"joint {joint.name!r} is defined twice")
            if joint.child in self._by_child:
                raise RobotModelError(
                    source,
                    f"link {joint.child!r} has two parent joints ({self._by_child[joint.child].name!r}, "
                    f"{joint.name!r}): not a tree",
                )
            self.joints[joint.name] = joint
            self._by_child[joint.child] = joint
        parents = {j.parent for j in joints}
        roots = sorted(parents - set(self._by_child))
        if len(roots) != 1:
            raise RobotModelError(source, f"expected one root link, found {roots or 'none (a cycle)'}")
        self.root: str = roots[0]
        for joint in joints:
            if joint.mimic is not None and joint.mimic.joint not in self.joints:
                raise RobotModelError(
                    source, f"joint {joint.name!r} mimics unknown joint {joint.mimic.joint!r}"
                )
        #: Joints that take a position of their own (moving, not mimic), in URDF order.
        self.actuated: tuple[str, ...] = tuple(j.name for j in joints if j.moves and j.mimic is None)
        #: Every link, root first, parents before children.
        self.links: tuple[str, ...] = (self.root, *[j.child for j in self._topological()])
        self._steps = {j.name: _step(j) for j in joints}

    # ----------------------------------------------------------------------------- construction

    @classmethod
    def from_urdf(cls, path: str | Path) -> RobotModel:
        """Parse a URDF file with yourdfpy (meshes not loaded; missing mesh files are fine)."""
        urdf = read_urdf(Path(path))
        if urdf.unsupported:
            name, jtype = urdf.unsupported[0]
            raise RobotModelError(urdf.source, f"joint {name!r} has type {jtype!r}; supported: "
                                  f"{[t.value for t in JointType]}")
        return cls(urdf.joints, source=urdf.source, name=urdf.name)

    # ----------------------------------------------------------------------------- structure

    def _topological(self) -> list[Joint]:
        children: dict[str, list[Joint]] = {}
        for joint in self.joints.values():
            children.setdefault(joint.parent, []).append(joint)
        order: list[Joint] = []
        stack = [self.root]
        while stack:
            link = stack.pop()
            for joint in reversed(children.get(link, [])):
                order.append(joint)
                stack.append(joint.child)
        if len(order) != len(self.joints):
            raise RobotModelError(self.source, "some joints are not connected to the root")
        # Depth-first pushes reverse siblings; parents still precede children.
        return order

    def has_link(self, link: str) -> bool:
        return link == self.root or link in self._by_child

    def path_joints(self, link: str, *, base: str | None = None) -> tuple[Joint, ...]:
        """Joints from ``base`` (default the root) down to ``link``; ``base`` must be an ancestor."""
        self._check_link(link)
        start = self.root if base is None else base
        self._check_link(start)
        out: list[Joint] = []
        cur = link
        while cur != start:
            joint = self._by_child.get(cur)
            if joint is None:
                raise RobotModelError(self.source, f"link {start!r} is not an ancestor of {link!r}")
            out.append(joint)
            cur = joint.parent
        return tuple(reversed(out))

    def limits(self, joint: str) -> tuple[float | None, float | None]:
        j = self._joint(joint)
        return j.lower, j.upper

    def _joint(self, name: str) -> Joint:
        try:
            return self.joints[name]
        except KeyError:
            raise RobotModelError(
                self.source, f"no joint {name!r}; joints are {sorted(self.joints)}"
            ) from None

    def _check_link(self, link: str) -> None:
        if not self.has_link(link):
            raise RobotModelError(self.source, f"no link {link!r}; links are {sorted(self.links)}")

    # ----------------------------------------------------------------------------- positions

    def positions(
        self, q: Mapping[str, npt.ArrayLike] | npt.ArrayLike, *, default: float | None = None
    ) -> dict[str, FloatArray]:
        """Every moving joint's positions ``(T,)``, mimic joints derived.

        ``q`` is a mapping ``joint -> (T,)`` (scalars broadcast) or a ``(T, J)`` array in the order
        of :attr:`actuated`. Actuated joints missing from a mapping take ``default`` (an error when
        None).
        """
        if isinstance(q, Mapping):
            given = {str(k): np.atleast_1d(np.asarray(v, dtype=float)) for k, v in q.items()}
            for name in given:
                self._joint(name)
        else:
            arr = np.asarray(q, dtype=float)
            if arr.ndim == 1:
                arr = arr[None, :]
            if arr.ndim != 2 or arr.shape[1] != len(self.actuated):
                raise RobotModelError(
                    self.source,
                    f"joint array has shape {arr.shape}; expected (T, {len(self.actuated)}) ordered as "
                    f"{list(self.actuated)}",
                )
            given = {name: arr[:, i] for i, name in enumerate(self.actuated)}
        lengths = {v.shape[0] for v in given.values() if v.shape[0] != 1}
        if len(lengths) > 1:
            raise RobotModelError(self.source, f"joint position arrays differ in length: {sorted(lengths)}")
        n = lengths.pop() if lengths else 1
        out: dict[str, FloatArray] = {}
        for name in self.actuated:
            if name in given:
                out[name] = np.broadcast_to(given[name], (n,)).astype(float)
            elif default is not None:
                out[name] = np.full(n, float(default))
            else:
                missing = [a for a in self.actuated if a not in given]
                raise RobotModelError(self.source, f"no positions for joints {missing}")
        for joint in self.joints.values():
            if joint.mimic is not None:
                src = joint.mimic
                if src.joint not in out:
                    raise RobotModelError(self.source, f"joint {joint.name!r} mimics a joint without positions")
                out[joint.name] = src.multiplier * out[src.joint] + src.offset
            elif joint.name in given and joint.name not in out:  # a fixed joint given a value: ignored
                continue
        return out

    # ----------------------------------------------------------------------------- kinematics

    def joint_poses(
        self, q: Mapping[str, npt.ArrayLike] | npt.ArrayLike, *, joints: Iterable[str] | None = None,
        default: float | None = None,
    ) -> dict[str, tuple[FloatArray, FloatArray]]:
        """Local ``T_parent_child`` of each joint as ``(translation (T, 3), quat_xyzw (T, 4))``.

        Fixed joints (and moving joints without positions) give one row.
        """
        pos = self.positions(q, default=default)
        names = list(self.joints) if joints is None else list(joints)
        out: dict[str, tuple[FloatArray, FloatArray]] = {}
        for name in names:
            step = self._steps[self._joint(name).name]
            quat, trans = _local(step, pos.get(name))
            m = max(np.size(c) for c in (*quat, *trans))
            out[name] = (_stack(trans, m), _stack(quat, m))
        return out

    def joint_transforms(
        self, q: Mapping[str, npt.ArrayLike] | npt.ArrayLike, *, joints: Iterable[str] | None = None,
        default: float | None = None,
    ) -> dict[str, FloatArray]:
        """Local ``T_parent_child`` of each joint at every frame, ``(T, 4, 4)`` (fixed: ``(1, 4, 4)``)."""
        pos = self.positions(q, default=default)
        names = list(self.joints) if joints is None else list(joints)
        out: dict[str, FloatArray] = {}
        for name in names:
            quat, trans = _local(self._steps[self._joint(name).name], pos.get(name))
            out[name] = homogeneous(quat, trans)
        return out

    def link_poses(
        self, q: Mapping[str, npt.ArrayLike] | npt.ArrayLike, *, links: Iterable[str] | None = None,
        default: float | None = None,
    ) -> dict[str, FloatArray]:
        """``T_root_link`` of each requested link (default: every link) at every frame, ``(T, 4, 4)``."""
        pos = self.positions(q, default=default)
        n = next(iter(pos.values())).shape[0] if pos else 1
        wanted = list(self.links) if links is None else list(links)
        for link in wanted:
            self._check_link(link)
        identity: tuple[Quat, Vec] = (_IDENTITY_Q, _ZERO_T)
        cache: dict[str, tuple[Quat, Vec]] = {self.root: identity}

        def pose(link: str) -> tuple[Quat, Vec]:
            if link not in cache:
                joint = self._by_child[link]
                parent = pose(joint.parent)
                cache[link] = _compose(parent, _local(self._steps[joint.name], pos.get(joint.name)))
            return cache[link]

        out: dict[str, FloatArray] = {}
        for link in wanted:
            quat, trans = pose(link)
            out[link] = np.broadcast_to(homogeneous(quat, trans), (n, 4, 4)).copy()
        return out

    def fk(
        self, q: Mapping[str, npt.ArrayLike] | npt.ArrayLike, link: str, *, default: float | None = None
    ) -> FloatArray:
        """``T_root_link`` at every frame, ``(T, 4, 4)`` (chained in cache-sized blocks)."""
        pos = self.positions(q, default=default)
        n = next(iter(pos.values())).shape[0] if pos else 1
        path = self.path_joints(link)
        out = np.empty((n, 4, 4))
        for lo in range(0, n, FK_BLOCK):
            hi = min(lo + FK_BLOCK, n)
            acc: tuple[Quat, Vec] = (_IDENTITY_Q, _ZERO_T)
            for joint in path:
                theta = pos.get(joint.name)
                acc = _compose(acc, _local(self._steps[joint.name], None if theta is None else theta[lo:hi]))
            out[lo:hi] = homogeneous(*acc, n=hi - lo)
        return out

    def fk_path(self, q: npt.ArrayLike, path: Sequence[Joint]) -> tuple[FloatArray, FloatArray]:
        """Chain the given joints with positions ``q`` (T, len(path)) (columns of fixed joints ignored).

        Returns ``(translation (T, 3), quat_xyzw (T, 4))`` of ``T_start_end``: the hot path the
        benchmark measures (mimic relations are not applied here).
        """
        arr = np.asarray(q, dtype=float)
        n = arr.shape[0]
        trans = np.empty((n, 3))
        quat = np.empty((n, 4))
        # Blocks small enough that the ~30 intermediate arrays stay in cache.
        for lo in range(0, max(n, 1), FK_BLOCK):
            block = arr[lo:lo + FK_BLOCK].T
            m = block.shape[1]
            acc: tuple[Quat, Vec] = (_IDENTITY_Q, _ZERO_T)
            for i, joint in enumerate(path):
                acc = _compose(acc, _local(self._steps[joint.name], block[i] if joint.moves else None))
            trans[lo:lo + m] = _stack(acc[1], m)
            quat[lo:lo + m] = _stack(acc[0], m)
        return trans, quat


def _step(joint: Joint) -> _Step:
    R0 = joint.origin[:3, :3]
    x, y, z, w = (float(c) for c in quat_from_matrix(R0))
    q0 = (x, y, z, w)
    a = joint.axis
    qa = quat_multiply(q0, (float(a[0]), float(a[1]), float(a[2]), 0.0))
    d = R0 @ a
    t0 = joint.origin[:3, 3]
    return _Step(
        joint, q0, (float(t0[0]), float(t0[1]), float(t0[2])),
        tuple(float(x) for x in qa) if joint.type in (JointType.REVOLUTE, JointType.CONTINUOUS)  # type: ignore[arg-type]
        else (0.0, 0.0, 0.0, 0.0),
        (float(d[0]), float(d[1]), float(d[2])) if joint.type is JointType.PRISMATIC else (0.0, 0.0, 0.0),
    )


def _local(step: _Step, theta: FloatArray | None) -> tuple[Quat, Vec]:
    """The joint's local ``(quat_xyzw, translation)`` at ``theta`` (constants when it has none)."""
    joint = step.joint
    if theta is None or not joint.moves:
        return step.q0, step.t0
    if joint.type is JointType.PRISMATIC:
        d, t0 = step.d, step.t0
        return step.q0, (t0[0] + theta * d[0], t0[1] + theta * d[1], t0[2] + theta * d[2])
    half = 0.5 * theta
    c, s = np.cos(half), np.sin(half)
    q0, qa = step.q0, step.qa
    return (c * q0[0] + s * qa[0], c * q0[1] + s * qa[1], c * q0[2] + s * qa[2], c * q0[3] + s * qa[3]), step.t0


_IDENTITY_Q: Quat = (0.0, 0.0, 0.0, 1.0)
_ZERO_T: Vec = (0.0, 0.0, 0.0)


def _compose(parent: tuple[Quat, Vec], child: tuple[Quat, Vec]) -> tuple[Quat, Vec]:
    """``T_a_c = T_a_b @ T_b_c`` on (quat, translation) component poses; the root passes through."""
    qp, tp = parent
    qc, tc = child
    if qp is _IDENTITY_Q and tp is _ZERO_T:  # the root: nothing to compose
        return child
    t, q = compose(tp, qp, tc, qc)
    return q, t


def _stack(parts: QuatLike | VecLike, n: int) -> FloatArray:
    return np.stack([np.broadcast_to(np.asarray(c, dtype=float), (n,)) for c in parts], axis=1)
