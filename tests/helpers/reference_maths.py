"""Independent reference maths for the geometry, timeline and replay tests: one time at a time, plain numpy and scipy.

Nothing here calls framechain's interpolation or quaternion code: the reference finds the
bracketing samples itself, interpolates translations linearly, rotations with scipy's Slerp, and
composes 4x4 matrices.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation, Slerp

from framechain.timeline import TransformTable

FloatArray = npt.NDArray[np.float64]

OK, NEAREST, PAST, FUTURE, NO_PATH = 0, 1, 2, 3, 4


@dataclass
class RefEdge:
    """Samples of ``T_parent_child`` for the reference (sorted, unique stamps)."""

    parent: str
    child: str
    stamps: npt.NDArray[np.int64]
    translation: FloatArray  # (n, 3)
    quat_xyzw: FloatArray  # (n, 4)
    is_static: bool = False

    def table(self) -> TransformTable:
        return TransformTable.from_rows(
            self.parent, self.child, self.stamps, self.translation, self.quat_xyzw, is_static=self.is_static
        )


def matrix(translation: npt.ArrayLike, quat_xyzw: npt.ArrayLike) -> FloatArray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat(np.asarray(quat_xyzw, dtype=float)).as_matrix()
    out[:3, 3] = np.asarray(translation, dtype=float)
    return out


def edge_at(edge: RefEdge, t: int) -> tuple[int, FloatArray]:
    """(status, 4x4 T_parent_child) of one edge at one time, tf2 style, written from scratch."""
    if edge.is_static:
        return OK, matrix(edge.translation[-1], edge.quat_xyzw[-1])
    stamps = [int(s) for s in edge.stamps]
    if t < stamps[0]:
        return PAST, np.full((4, 4), np.nan)
    if t > stamps[-1]:
        return FUTURE, np.full((4, 4), np.nan)
    for i, s in enumerate(stamps):
        if s == t:
            return OK, matrix(edge.translation[i], edge.quat_xyzw[i])
    i = max(k for k, s in enumerate(stamps) if s < t)
    t0, t1 = stamps[i], stamps[i + 1]
    w = (t - t0) / (t1 - t0)
    trans = (1 - w) * edge.translation[i] + w * edge.translation[i + 1]
    slerp = Slerp([0.0, 1.0], Rotation.from_quat(edge.quat_xyzw[i : i + 2]))
    return OK, matrix(trans, slerp([w]).as_quat()[0])


def path_edges(edges: Sequence[RefEdge], target: str, source: str) -> list[tuple[RefEdge, bool]] | None:
    """Edges from source to target as (edge, inverse); None when not connected."""
    by_child = {e.child: e for e in edges}

    def up(frame: str) -> list[str]:
        chain = [frame]
        while chain[-1] in by_child:
            chain.append(by_child[chain[-1]].parent)
        return chain

    a, b = up(source), up(target)
    common = next((f for f in a if f in b), None)
    if common is None:
        return None
    hops = [(by_child[f], False) for f in a[: a.index(common)]]
    hops += [(by_child[f], True) for f in reversed(b[: b.index(common)])]
    return hops


def reference_lookup(edges: Sequence[RefEdge], target: str, source: str, t: int) -> tuple[int, FloatArray]:
    """(status, T_target_source) at one time by composing 4x4 matrices hop by hop."""
    hops = path_edges(edges, target, source)
    if hops is None:
        return NO_PATH, np.full((4, 4), np.nan)
    status = OK
    current = np.eye(4)  # T_frame_source, frame walking from source to target
    for edge, inverse in hops:
        s, m = edge_at(edge, t)
        status = max(status, s)
        current = (np.linalg.inv(m) if inverse else m) @ current
    if status != OK:
        return status, np.full((4, 4), np.nan)
    return status, current


def random_quats(rng: np.random.Generator, n: int) -> FloatArray:
    q = rng.normal(size=(n, 4))
    out: FloatArray = q / np.linalg.norm(q, axis=1, keepdims=True)
    return out


def assert_same_rotation(q1: npt.ArrayLike, q2: npt.ArrayLike, atol: float = 1e-12) -> None:
    """Quaternions (N, 4) equal component by component up to the sign of the whole quaternion."""
    a, b = np.atleast_2d(np.asarray(q1, dtype=float)), np.atleast_2d(np.asarray(q2, dtype=float))
    sign = np.where(np.sum(a * b, axis=1) < 0, -1.0, 1.0)
    np.testing.assert_allclose(a, b * sign[:, None], rtol=0, atol=atol)
