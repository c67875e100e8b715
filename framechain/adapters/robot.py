"""A robot model from a URDF and batched forward kinematics over whole episodes.

yourdfpy parses the URDF (meshes are never loaded); everything after parsing is NumPy. Forward
kinematics runs on whole arrays of joint positions, one ``(T, 4, 4)`` stack per link, never one
Python call per frame:

- :meth:`RobotModel.joint_transforms` gives each joint's local transform ``T_parent_child`` at
  every frame (origin @ motion), the rows a Timeline stores;
- :meth:`RobotModel.link_poses` chains them from the root, ``T_root_link`` per link.

Chaining does not multiply ``(T, 4, 4)`` stacks (NumPy's batched 4x4 matmul costs about 180 ns a
product). A revolute joint's local rotation is ``R0 @ Rot(a, q) = P + cos(q) Q + sin(q) S`` with
constant ``P = R0 a a^T``, ``Q = R0 (I - a a^T)``, ``S = R0 [a]_x``; so the parent pose times the
joint is one BLAS product ``R_parent @ [P | Q | S | p0]`` over all frames at once, followed by
two scaled additions. A 6-joint arm chains at several million configurations a second
(``benchmarks/bench_fk.py``).

Conventions: ``T_a_b`` maps points in frame b into frame a; joint positions are SI (radians for
revolute and continuous joints, metres for prismatic ones); a mimic joint follows
``q = multiplier * q_source + offset``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np
import numpy.typing as npt

from framechain.timeline import FramechainError

FloatArray = npt.NDArray[np.float64]

__all__ = [
    "Joint",
    "JointType",
    "Mimic",
    "RobotModel",
    "RobotModelError",
]


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


@dataclass(frozen=True)
class _Step:
    """A joint's constants for the chained product (see the module docstring)."""

    joint: Joint
    #: revolute: [P | Q | S | p0] (3x10); prismatic: [R0 | p0 | R0 a] (3x5); fixed: [R0 | p0] (3x4)
    block: FloatArray


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
        self._steps = {j.name: _Step(j, _block(j)) for j in joints}

    # ----------------------------------------------------------------------------- construction

    @classmethod
    def from_urdf(cls, path: str | Path) -> RobotModel:
        """Parse a URDF file with yourdfpy (meshes not loaded; missing mesh files are fine)."""
        import yourdfpy

        p = Path(path)
        if not p.is_file():
            raise RobotModelError(str(p), "URDF file not found")
        try:
            urdf = yourdfpy.URDF.load(
                str(p), build_scene_graph=False, load_meshes=False,
                build_collision_scene_graph=False, load_collision_meshes=False,
            )
        except Exception as err:  # yourdfpy raises lxml, ValueError, KeyError... on bad files
            raise RobotModelError(str(p), f"cannot parse URDF ({type(err).__name__}: {err})") from err
        joints: list[Joint] = []
        for raw in urdf.robot.joints:
            try:
                jtype = JointType(raw.type)
            except ValueError:
                raise RobotModelError(
                    str(p), f"joint {raw.name!r} has type {raw.type!r}; supported: {[t.value for t in JointType]}"
                ) from None
            origin = np.eye(4) if raw.origin is None else np.asarray(raw.origin, dtype=float)
            axis = np.array([1.0, 0.0, 0.0]) if raw.axis is None else np.asarray(raw.axis, dtype=float)
            if jtype is not JointType.FIXED:
                norm = float(np.linalg.norm(axis))
                if not np.isfinite(norm) or norm < 1e-12:
                    raise RobotModelError(str(p), f"joint {raw.name!r} has a zero axis")
                axis = axis / norm
            lower = upper = None
            if raw.limit is not None and jtype is not JointType.CONTINUOUS:
                lower = None if raw.limit.lower is None else float(raw.limit.lower)
                upper = None if raw.limit.upper is None else float(raw.limit.upper)
            mimic = None
            if raw.mimic is not None:
                mimic = Mimic(
                    str(raw.mimic.joint),
                    1.0 if raw.mimic.multiplier is None else float(raw.mimic.multiplier),
                    0.0 if raw.mimic.offset is None else float(raw.mimic.offset),
                )
            joints.append(Joint(str(raw.name), jtype, str(raw.parent), str(raw.child), origin, axis,
                                lower, upper, mimic))
        return cls(joints, source=str(p), name=str(urdf.robot.name or ""))

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

    def parent_joint(self, link: str) -> Joint | None:
        """The joint whose child is ``link`` (None for the root)."""
        self._check_link(link)
        return self._by_child.get(link)

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

    def joint_transforms(
        self, q: Mapping[str, npt.ArrayLike] | npt.ArrayLike, *, joints: Iterable[str] | None = None,
        default: float | None = None,
    ) -> dict[str, FloatArray]:
        """Local ``T_parent_child`` of each joint at every frame, ``(T, 4, 4)`` (fixed: ``(1, 4, 4)``)."""
        pos = self.positions(q, default=default)
        n = next(iter(pos.values())).shape[0] if pos else 1
        names = list(self.joints) if joints is None else list(joints)
        out: dict[str, FloatArray] = {}
        for name in names:
            step = self._steps[self._joint(name).name]
            theta = pos.get(name)
            R, p = _chain(None, None, step, theta, 1 if theta is None else n)
            out[name] = _homogeneous(R, p)
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
        cache: dict[str, tuple[FloatArray | None, FloatArray | None]] = {self.root: (None, None)}

        def pose(link: str) -> tuple[FloatArray | None, FloatArray | None]:
            if link in cache:
                return cache[link]
            joint = self._by_child[link]
            R_parent, p_parent = pose(joint.parent)
            theta = pos.get(joint.name)
            cache[link] = _chain(R_parent, p_parent, self._steps[joint.name], theta, n)
            return cache[link]

        out: dict[str, FloatArray] = {}
        for link in wanted:
            R, p = pose(link)
            if R is None or p is None:
                out[link] = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
            else:
                out[link] = _homogeneous(np.broadcast_to(R, (n, 3, 3)), np.broadcast_to(p, (n, 3)))
        return out

    def fk(
        self, q: Mapping[str, npt.ArrayLike] | npt.ArrayLike, link: str, *, default: float | None = None
    ) -> FloatArray:
        """``T_root_link`` at every frame, ``(T, 4, 4)``."""
        return self.link_poses(q, links=[link], default=default)[link]

    def fk_path(self, q: npt.ArrayLike, path: Sequence[Joint]) -> tuple[FloatArray, FloatArray]:
        """Chain the given joints with positions ``q`` (T, len(path)) (0 columns for fixed ones).

        Returns ``(R, p)``, ``(T, 3, 3)`` and ``(T, 3)``: the hot path the benchmark measures.
        """
        arr = np.asarray(q, dtype=float)
        n = arr.shape[0]
        R: FloatArray | None = None
        p: FloatArray | None = None
        for i, joint in enumerate(path):
            R, p = _chain(R, p, self._steps[joint.name], arr[:, i] if joint.moves else None, n)
        if R is None or p is None:
            return np.broadcast_to(np.eye(3), (n, 3, 3)).copy(), np.zeros((n, 3))
        return np.broadcast_to(R, (n, 3, 3)), np.broadcast_to(p, (n, 3))


def _skew(a: FloatArray) -> FloatArray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _block(joint: Joint) -> FloatArray:
    R0 = joint.origin[:3, :3]
    p0 = joint.origin[:3, 3:4]
    a = joint.axis
    if joint.type in (JointType.REVOLUTE, JointType.CONTINUOUS):
        aa = np.outer(a, a)
        return np.hstack([R0 @ aa, R0 @ (np.eye(3) - aa), R0 @ _skew(a), p0])
    if joint.type is JointType.PRISMATIC:
        return np.hstack([R0, p0, (R0 @ a)[:, None]])
    return np.hstack([R0, p0])


def _chain(
    R_parent: FloatArray | None, p_parent: FloatArray | None, step: _Step, theta: FloatArray | None, n: int
) -> tuple[FloatArray, FloatArray]:
    """``T_root_child = T_root_parent @ origin @ motion(theta)``, vectorised over frames.

    ``R_parent``/``p_parent`` None means the identity (the root). A fixed joint, or a moving one
    given no positions, returns a (1, ...) stack when its parent is the root.
    """
    joint, block = step.joint, step.block
    if R_parent is None or p_parent is None:
        X = block[None, :, :]  # (1, 3, k)
        base_p = np.zeros((1, 3))
    else:
        m = R_parent.shape[0]
        X = (R_parent.reshape(m * 3, 3) @ block).reshape(m, 3, block.shape[1])
        base_p = p_parent
    if not joint.moves:
        return X[:, :, 0:3], base_p + X[:, :, 3]
    if theta is None:
        theta = np.zeros(n)
    if joint.type is JointType.PRISMATIC:
        return X[:, :, 0:3], base_p + X[:, :, 3] + theta[:, None] * X[:, :, 4]
    c = np.cos(theta)[:, None, None]
    s = np.sin(theta)[:, None, None]
    R = X[:, :, 0:3] + c * X[:, :, 3:6] + s * X[:, :, 6:9]
    return R, base_p + X[:, :, 9]


def _homogeneous(R: FloatArray, p: FloatArray) -> FloatArray:
    n = max(R.shape[0], p.shape[0])
    out = np.zeros((n, 4, 4))
    out[:, :3, :3] = R
    out[:, :3, 3] = p
    out[:, 3, 3] = 1.0
    return out
