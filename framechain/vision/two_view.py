"""A camera's rotation between two frames from matched bearing vectors, for many frame pairs at once.

Every function works on a :class:`PairBatch`: P frame pairs, each with up to M matched unit
bearings ``b0`` (earlier frame) and ``b1`` (later frame) in the optical frame, padded to ``(P, M, 3)``
with a ``valid`` mask, so one NumPy pass serves all pairs (no Python loop per pair).

The rotation ``R = R_cam0_cam1`` maps the later frame's bearings to the earlier one's: for a far
point ``b0 = R b1``; a point at inverse distance ``rho`` when the camera centre moves by ``t``
(earlier frame) gives ``b0 ~ R b1 + rho t``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from framechain.arrays import BoolArray, FloatArray, IntArray
from framechain.geometry.rotations import kabsch
from framechain.vision.threads import by_row_blocks

__all__ = [
    "PairBatch",
    "off_flow_residuals",
    "rotation_matrices",
    "rotations_along_translation",
    "rotations_ransac",
    "translation_directions",
]


@dataclass(frozen=True)
class PairBatch:
    """P pairs of matched unit bearings, padded: ``b0``, ``b1`` (P, M, 3), ``valid`` (P, M)."""

    b0: FloatArray
    b1: FloatArray
    valid: BoolArray


def rotation_matrices(rotvec: FloatArray) -> FloatArray:
    """Rodrigues: rotation vectors (..., 3) to matrices (..., 3, 3)."""
    angle = np.linalg.norm(rotvec, axis=-1)
    safe = np.where(angle > 1e-12, angle, 1.0)
    axis = rotvec / safe[..., None]
    k = np.zeros((*rotvec.shape[:-1], 3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -axis[..., 2], axis[..., 1], -axis[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = axis[..., 2], -axis[..., 1], axis[..., 0]
    s = np.where(angle > 1e-12, np.sin(angle), angle)[..., None, None]
    c = (1.0 - np.cos(angle))[..., None, None]
    out: FloatArray = np.eye(3) + s * k + c * (k @ k)
    return out


def rotations_ransac(
    batch: PairBatch, threshold_rad: float, *, hypotheses: int, rng: np.random.Generator
) -> tuple[FloatArray, BoolArray]:
    """Rotation-only RANSAC per pair: ``R`` (P, 3, 3) with ``b0 ~ R b1``, inliers (P, M) within ``threshold_rad``.

    Two-point Kabsch hypotheses (two distinct valid matches of the pair), all scored at once; the
    best of each pair is refitted on its inliers twice.
    """
    p = batch.b0.shape[0]
    count = np.maximum(batch.valid.sum(axis=1), 2)
    # Valid matches come first in each row, so indices below the count are valid.
    first = (rng.random((p, hypotheses)) * count[:, None]).astype(np.int64)
    second = (first + 1 + (rng.random((p, hypotheses)) * (count[:, None] - 1)).astype(np.int64)) % count[:, None]

    def block(part: slice) -> tuple[FloatArray, BoolArray]:  # each pair's hypotheses drawn above: the same numbers
        return _ransac(PairBatch(batch.b0[part], batch.b1[part], batch.valid[part]), first[part], second[part],
                       threshold_rad)

    return by_row_blocks(block, p, SPLIT_PAIRS)


def _ransac(batch: PairBatch, first: IntArray, second: IntArray, threshold_rad: float) -> tuple[FloatArray, BoolArray]:
    """:func:`rotations_ransac` of the pairs of ``batch`` from the matches each hypothesis draws (P, H)."""
    p, hypotheses = first.shape
    rows = np.arange(p)[:, None]
    cross = (batch.b0[rows, first][..., :, None] * batch.b1[rows, first][..., None, :]
             + batch.b0[rows, second][..., :, None] * batch.b1[rows, second][..., None, :])
    candidates = kabsch(cross)  # (P, H, 3, 3)
    cos_limit = np.cos(threshold_rad)
    # b0 . R b1 = sum_ij R_ij (b0 b1^T)_ij: one batched product of (H, 9) by (9, M) per pair.
    outer = (batch.b0[..., :, None] * batch.b1[..., None, :]).reshape(p, -1, 9)
    scores = np.empty((p, hypotheses), dtype=np.int64)
    for lo in range(0, p, _CHUNK):
        agree = candidates[lo:lo + _CHUNK].reshape(-1, hypotheses, 9) @ np.swapaxes(outer[lo:lo + _CHUNK], 1, 2)
        scores[lo:lo + _CHUNK] = ((agree > cos_limit) & batch.valid[lo:lo + _CHUNK, None, :]).sum(axis=2)
    best = candidates[np.arange(p), np.argmax(scores, axis=1)]
    inliers = _agreeing(outer, batch.valid, best, cos_limit)
    for _ in range(2):
        best = kabsch((inliers[:, None, :] @ outer).reshape(p, 3, 3))
        inliers = _agreeing(outer, batch.valid, best, cos_limit)
    return best, inliers


#: Pairs scored per batched product in :func:`rotations_ransac` (bounds the (P, H, M) scores in memory).
_CHUNK = 64


def _agreeing(outer: FloatArray, valid: BoolArray, rotation: FloatArray, cos_limit: float) -> BoolArray:
    cosine = (outer @ rotation.reshape(-1, 9, 1))[..., 0]
    out: BoolArray = (cosine > cos_limit) & valid
    return out


def _across(b0: FloatArray, v: FloatArray) -> FloatArray:
    """The part of ``v`` (..., 3) across the unit bearings ``b0`` (the tangent plane at ``b0``)."""
    out: FloatArray = v - (v * b0).sum(axis=-1, keepdims=True) * b0
    return out


def off_flow_residuals(batch: PairBatch, rotation: FloatArray, direction: FloatArray) -> FloatArray:
    """Per match, the part of ``R b1`` across ``b0`` that no positive depth along ``direction`` explains (P, M, 3)."""
    u = batch.b1 @ np.swapaxes(rotation, 1, 2)
    across_u = _across(batch.b0, u)
    across_t = _across(batch.b0, direction[:, None, :])
    rho = np.clip(-(across_u * across_t).sum(-1) / np.maximum((across_t**2).sum(-1), 1e-18), 0.0, None)
    out: FloatArray = across_u + rho[..., None] * across_t
    return out


#: Frame pairs per block when :func:`rotations_along_translation` splits them over the run's threads: fewer would
#: spend more on the blocks' own NumPy calls than the threads give back.
SPLIT_PAIRS = 128


def rotations_along_translation(
    batch: PairBatch, rotation: FloatArray, direction: FloatArray, weights: FloatArray, threshold_rad: float,
    iterations: int,
) -> tuple[FloatArray, FloatArray]:
    """:func:`_rotations_along_translation` of blocks of the pairs at once, one per thread this camera may use
    (:func:`~framechain.vision.threads.threads_here`; each pair's measurement is its own: the same numbers as one
    block, to the last bit). A generated 640x480 AV1 episode, one camera on 2 cores: attributed in 3.0 s against 3.9
    s in one block; two cameras measured at once gain nothing (each has one core)."""

    def block(part: slice) -> tuple[FloatArray, FloatArray]:
        sub = PairBatch(batch.b0[part], batch.b1[part], batch.valid[part])
        return _rotations_along_translation(sub, rotation[part], direction[part], weights[part], threshold_rad,
                                            iterations)

    return by_row_blocks(block, rotation.shape[0], SPLIT_PAIRS)


def _rotations_along_translation(
    batch: PairBatch, rotation: FloatArray, direction: FloatArray, weights: FloatArray, threshold_rad: float,
    iterations: int,
) -> tuple[FloatArray, FloatArray]:
    """``R`` (P, 3, 3) with ``b0 ~ R b1 + rho t`` for known translation directions ``t`` (P, 3), ``rho >= 0``, and
    each match's off-flow residual there (P, M): the norm of :func:`off_flow_residuals` to a few ULPs, the whole
    residual at the epipole (a flow under 1e-12) for both; between 1e-12 and 1e-9 that one clamps the flow it
    scales by, and the two differ.

    The inverse depths are projected out: a match's residual is the part of ``R b1`` across ``b0``
    that is not along the translation's flow at ``b0`` (all of it where that would need a negative
    depth). Gauss-Newton on the rotation from ``rotation``, with Cauchy weights whose scale anneals
    from eight times ``threshold_rad`` down to it (halving per step); ``weights`` (P, M) zero the
    matches left out. A pair stops once the weights have annealed and its step is under 1e-7 rad.
    """
    # Vectors are held component first, (3, P, M): a product summed over three contiguous planes is about three
    # times faster than over a trailing axis of three, and this loop is most of what a camera's motion costs.
    b0, b1 = np.moveaxis(batch.b0, -1, 0).copy(), np.moveaxis(batch.b1, -1, 0).copy()
    # The tangent plane at b0 in a basis fixed by the translation: ``along`` its flow, ``across`` normal to it. A
    # match's residual is (across . u, along . u) for u = R b1, its along part dropped when negative (a positive
    # depth explains it: "ahead"). Where b0 is the epipole the flow has no direction and a spare tangent basis
    # stands in (in practice only the padding, whose weight is zero).
    t = direction.T[:, :, None]
    flow = t - _dot(t, b0) * b0
    size = np.sqrt(_dot(flow, flow))
    spare = _spare_tangent(b0)
    along = np.where(size > 1e-12, flow / np.maximum(size, 1e-12), spare)
    across = _cross(b0, along)
    rot = np.array(rotation, dtype=float, copy=True)
    # Only the pairs still moving are iterated: after the annealing most settle in a step or two, a few take all.
    index = np.arange(rot.shape[0])
    moving = (rot, b1, across, along, weights)
    for it in range(iterations):
        if index.size == 0:
            break
        step = _gauss_newton_step(*moving, threshold_rad * max(1.0, 8.0 * 0.5**it))
        moving = (rotation_matrices(step) @ moving[0], *moving[1:])
        rot[index] = moving[0]
        if it >= _ANNEALED:
            keep = np.abs(step).max(axis=1) >= 1e-7
            if not keep.all():
                index = index[keep]
                moving = (moving[0][keep], *(a[:, keep] for a in moving[1:4]), moving[4][keep])
    # In the basis built above the residual is (across . u, along . u), the along part only where it is not ahead;
    # at the epipole no depth moves the point, and all of it is residual.
    u = np.einsum("pij,jpm->ipm", rot, b1)
    r_along = _dot(along, u)[0]
    residual: FloatArray = np.hypot(_dot(across, u)[0], np.where(size[0] > 1e-12, np.maximum(r_along, 0.0), r_along))
    return rot, residual


def _spare_tangent(b0: FloatArray) -> FloatArray:
    """A unit vector across each unit bearing ``b0`` (3, P, M)."""
    helper = np.zeros_like(b0)
    x_ok = np.abs(b0[0]) < 0.9
    helper[0][x_ok] = 1.0
    helper[1][~x_ok] = 1.0
    v = _cross(b0, helper)
    out: FloatArray = v / np.sqrt(_dot(v, v))
    return out


#: The step from which the Cauchy scale of :func:`rotations_along_translation` is the threshold itself.
_ANNEALED = 3


def _gauss_newton_step(rot: FloatArray, b1: FloatArray, across: FloatArray, along: FloatArray, weights: FloatArray,
                       scale: float) -> FloatArray:
    """One Cauchy-weighted Gauss-Newton step of :func:`rotations_along_translation` (rotation vectors, (P, 3)).

    With ``d(u) = omega x u`` each residual component ``e . u`` has the gradient ``u x e``, so the normal
    matrix is the weighted sum of ``(u x e)(u x e)^T`` over the components kept."""
    u = np.einsum("pij,jpm->ipm", rot, b1)
    r_across = _dot(across, u)[0]
    r_along = _dot(along, u)[0]
    kept = r_along >= 0  # not ahead: no positive depth explains it
    r_along = np.where(kept, r_along, 0.0)
    w = weights / (1.0 + (r_across**2 + r_along**2) / scale**2)
    w_along = np.where(kept, w, 0.0)
    g_across, g_along = _cross(u, across), _cross(u, along)
    # einsum sums each pair's products in one pass (seven times faster than a sum per entry of the normal matrix).
    normal = (np.einsum("ipm,jpm->pij", w * g_across, g_across) + np.einsum("ipm,jpm->pij", w_along * g_along, g_along)
              + 1e-15 * np.eye(3))
    rhs = -(np.einsum("ipm,pm->pi", g_across, w * r_across) + np.einsum("ipm,pm->pi", g_along, w_along * r_along))
    out: FloatArray = np.linalg.solve(normal, rhs[..., None])[..., 0]
    return out


def _dot(a: FloatArray, b: FloatArray) -> FloatArray:
    """Dot products of component-first vectors (3, ...), kept as (1, ...)."""
    out: FloatArray = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2])[None]
    return out


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """Cross products of component-first vectors (3, ...), written in place (no stacked copy)."""
    out: FloatArray = np.empty(np.broadcast_shapes(a.shape, b.shape))
    for k, (i, j) in enumerate(((1, 2), (2, 0), (0, 1))):
        np.multiply(a[i], b[j], out=out[k])
        out[k] -= a[j] * b[i]
    return out


def _gram(weights: FloatArray, v: FloatArray) -> FloatArray:
    """``sum_m w v v^T`` per pair (P, 3, 3), for ``weights`` (P, M, 1) and ``v`` (P, M, 3)."""
    out: FloatArray = np.swapaxes(weights * v, 1, 2) @ v
    return out


def translation_directions(batch: PairBatch, rotation: FloatArray, weights: FloatArray) -> FloatArray:
    """Per pair, the epipolar translation direction given the rotation, signed by the flow (P, 3).

    The direction is normal to every ``R b1 x b0`` (weighted scatter's smallest eigenvector); a near
    point's derotated bearing moves away from the translation, which fixes the sign.
    """
    u = batch.b1 @ np.swapaxes(rotation, 1, 2)
    normals = np.cross(u, batch.b0)
    _values, vectors = np.linalg.eigh(_gram(weights[..., None], normals))
    t = vectors[..., 0]
    flow = u - batch.b0
    sign = (weights * (flow * _across(batch.b0, t[:, None, :])).sum(-1)).sum(1)
    out: FloatArray = np.where(sign[:, None] > 0, -t, t)
    return out
