"""Rigid transforms on rows, the layout tables hold: translations (N, 3), quaternions (N, 4) ordered
x, y, z, w, points (N, 3); a single row (one transform for every point) broadcasts.

``T_a_b`` maps points of frame b into frame a, so ``T_a_c = T_a_b @ T_b_c``. The maths is
:mod:`framechain.geometry.rotations` (components first), applied to ``rows.T`` views.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray
from framechain.geometry.rotations import compose, invert, quat_rotate

__all__ = ["compose_rows", "invert_rows", "transform_points"]


def transform_points(translation: npt.ArrayLike, quat_xyzw: npt.ArrayLike, points: npt.ArrayLike) -> FloatArray:
    """``p_a = T_a_b p_b`` row by row: transforms (N, 3)/(N, 4) applied to points (N, 3)."""
    out: FloatArray = quat_rotate(np.asarray(quat_xyzw).T, np.asarray(points).T).T + np.asarray(translation)
    return out


def compose_rows(t_ab: npt.ArrayLike, q_ab: npt.ArrayLike, t_bc: npt.ArrayLike, q_bc: npt.ArrayLike
                 ) -> tuple[FloatArray, FloatArray]:
    """Row-wise ``T_a_c = T_a_b @ T_b_c`` on (N, 3)/(N, 4) arrays."""
    t, q = compose(np.asarray(t_ab).T, np.asarray(q_ab).T, np.asarray(t_bc).T, np.asarray(q_bc).T)
    return t.T, q.T


def invert_rows(t_ab: npt.ArrayLike, q_ab: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Row-wise ``T_b_a`` from ``T_a_b`` on (N, 3)/(N, 4) arrays."""
    t, q = invert(np.asarray(t_ab, dtype=float).T, np.asarray(q_ab, dtype=float).T)
    return t.T, q.T
