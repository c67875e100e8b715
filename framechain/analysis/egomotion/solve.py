"""The camera-motion fit's numerics: the frame pairs, a link's rotation over time, the offset and mount solved at
once over a grid of trial offsets (weighted Kabsch per offset, one matrix product for all), the bootstrap, how
well the pairs pin each parameter, and the focal scale.

Private to :mod:`framechain.analysis.egomotion`: :mod:`.fit` puts these together.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from framechain.analysis.egomotion.model import EgoMotionFitOptions, LinkFit, LinkMotion, MountEvidence
from framechain.arrays import FloatArray
from framechain.geometry.rotations import (
    kabsch,
    quat_conjugate,
    quat_from_rotvec,
    quat_multiply,
    quat_of,
    quat_to_rotvec,
    rotvec_of,
)
from framechain.timeline import EgoMotionTable


@dataclass(frozen=True)
class Pairs:
    """The measured frame pairs used: times (s from the links' first stamp), rotation vectors, weights."""

    t0: FloatArray
    t1: FloatArray
    rotvec: FloatArray  # (N, 3) measured, optical frame
    weight: FloatArray

    @property
    def dt(self) -> FloatArray:
        out: FloatArray = self.t1 - self.t0
        return out


def frame_pairs(measured: EgoMotionTable, origin_ns: int, span_s: tuple[float, float], max_offset_s: float
                ) -> Pairs:
    """The pairs whose shifted times stay inside the links' span for every trial offset."""
    t0: FloatArray = (measured.stamp0_ns - origin_ns).astype(np.float64) * 1e-9
    t1: FloatArray = (measured.stamp1_ns - origin_ns).astype(np.float64) * 1e-9
    inside = (t0 - max_offset_s >= span_s[0]) & (t1 + max_offset_s <= span_s[1])
    inside &= np.isfinite(measured.quat_xyzw).all(axis=1)
    rotvec = rotvec_of(measured.quat_xyzw[inside])
    return Pairs(t0=t0[inside], t1=t1[inside], rotvec=rotvec, weight=np.ones(int(inside.sum())))


class Orientations:
    """A link's rotations over time, interpolated by slerp (vectorised; components first)."""

    def __init__(self, link: LinkMotion, origin_ns: int) -> None:
        self.times: FloatArray = ((np.asarray(link.stamps_ns, dtype=np.int64) - origin_ns) * 1e-9).astype(np.float64)
        quat = np.asarray(link.quat_xyzw, dtype=float).T
        self.quat: FloatArray = quat / np.linalg.norm(quat, axis=0)
        # The rotation from each sample to the next, as a rotation vector.
        self.step: FloatArray = quat_to_rotvec(quat_multiply(quat_conjugate(self.quat[:, :-1]), self.quat[:, 1:]))

    def at(self, times: FloatArray) -> FloatArray:
        """Quaternions (4, K) at ``times`` (clipped to the span: rounding at its ends)."""
        t = np.clip(times, self.times[0], self.times[-1])
        i = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, self.times.size - 2)
        alpha = (t - self.times[i]) / (self.times[i + 1] - self.times[i])
        return quat_multiply(self.quat[:, i], quat_from_rotvec(self.step[:, i] * alpha))


def link_rotvecs(orientations: Orientations, pairs: Pairs, offsets: FloatArray) -> FloatArray:
    """The link's predicted rotation vectors ``rotvec(R(t0+d)^T R(t1+d))``, ``(G, N, 3)`` for G offsets.

    The link is interpolated once per frame time and offset: pairs share their frames (consecutive and chained
    pairs of a few hundred frames), so a frame's orientation serves every pair it is in.
    """
    n = pairs.t0.size
    times, where = np.unique(np.concatenate([pairs.t0, pairs.t1]), return_inverse=True)
    at = orientations.at((times[None, :] + offsets[:, None]).ravel()).reshape(4, offsets.size, times.size)
    first, second = at[:, :, where[:n]].reshape(4, -1), at[:, :, where[n:]].reshape(4, -1)
    out: FloatArray = quat_to_rotvec(quat_multiply(quat_conjugate(first), second)).T.reshape(offsets.size, -1, 3)
    return out


class Scatter:
    """The products ``a b^T`` and ``|a|^2 + |b|^2`` of every pair at every trial offset, built once.

    ``link_rv`` (G, N, 3) are the link's rotation vectors at G offsets, ``cam_rv`` (N, 3) the measured
    ones, or (G, N, 3) when each offset has a measurement of its own (made with the translation prior of
    that offset, or interpolated between such); :meth:`fit` then weighs the pairs with one matrix product
    (BLAS), for one weight vector or a whole bootstrap at once. With ``dt`` (N,) the pairs' durations, a constant rate
    bias ``beta`` of the link's rotation is fitted too: ``a`` becomes ``a - beta dt``, alternating with
    the mount (one measurement only).
    """

    def __init__(self, link_rv: FloatArray, cam_rv: FloatArray, dt: FloatArray | None = None) -> None:
        g, n = link_rv.shape[:2]
        self.offsets = g
        per_offset = cam_rv.ndim == 3
        if per_offset and dt is not None:
            raise ValueError("a rate bias is fitted against one measurement, not one per offset")
        self.outer = np.einsum("gni,gnj->ngij" if per_offset else "gni,nj->ngij", link_rv, cam_rv).reshape(n, g * 9)
        cam_norms = (cam_rv**2).sum(-1) if per_offset else (cam_rv**2).sum(-1)[None]
        self.norms = ((link_rv**2).sum(-1) + cam_norms).T  # (N, G)
        self.dt = dt
        if dt is not None:
            self.link_dt = (link_rv * dt[None, :, None]).transpose(1, 0, 2).reshape(n, g * 3)
            self.cam_dt = cam_rv * dt[:, None]
            self.dt2 = dt**2

    def fit(self, weights: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Per offset (and per weight row): the mount ``X``, the misfit ``sum w |b - X^T a|^2`` and ``C = sum w a b^T``.

        ``weights`` (N,) or (B, N): mounts and ``C`` (G, 3, 3) or (B, G, 3, 3), misfits (G,) or (B, G).
        """
        w = np.atleast_2d(weights)
        cross = (w @ self.outer).reshape(w.shape[0], self.offsets, 3, 3)
        mounts = kabsch(cross)
        cost = w @ self.norms - 2.0 * (mounts * cross).sum(axis=(-1, -2))
        if self.dt is not None:
            mounts, cost, cross = self._with_bias(w, cross, mounts)
        if weights.ndim == 1:
            return mounts[0], cost[0], cross[0]
        return mounts, cost, cross

    def bias(self, weights: FloatArray, mount: FloatArray, offset: int) -> FloatArray:
        """The rate bias (rad/s, link frame) fitted with ``mount`` at offset index ``offset`` (one weight row)."""
        if self.dt is None:
            return np.zeros(3)
        s_adt = (weights @ self.link_dt).reshape(self.offsets, 3)[offset]
        s_bdt = weights @ self.cam_dt
        out: FloatArray = (s_adt - mount @ s_bdt) / max(float(weights @ self.dt2), 1e-18)
        return out

    def _with_bias(self, w: FloatArray, cross: FloatArray, mounts: FloatArray
                   ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Mount and bias in turn (three rounds): ``beta = sum w dt (a - X b) / sum w dt^2``, then Kabsch on
        ``C - beta (sum w dt b)^T``."""
        assert self.dt is not None
        s_adt = (w @ self.link_dt).reshape(w.shape[0], self.offsets, 3)  # (B, G, 3)
        s_bdt = w @ self.cam_dt  # (B, 3)
        s_dt2 = np.maximum(w @ self.dt2, 1e-18)[:, None, None]  # (B, 1, 1)
        biased = cross
        for _ in range(3):
            beta = (s_adt - np.einsum("bgij,bj->bgi", mounts, s_bdt)) / s_dt2
            biased = cross - beta[..., :, None] * s_bdt[:, None, None, :]
            mounts = kabsch(biased)
        cost = (w @ self.norms - 2.0 * (beta * s_adt).sum(-1) + (beta**2).sum(-1) * s_dt2[..., 0]
                - 2.0 * (mounts * biased).sum(axis=(-1, -2)))
        return mounts, cost, biased


def parabola_min(x: FloatArray, y: FloatArray) -> FloatArray:
    """Sub-grid minimum along the last axis of ``y`` over the even grid ``x`` (a parabola through three points)."""
    k = np.clip(np.argmin(y, axis=-1), 1, x.size - 2)
    y0 = np.take_along_axis(y, (k - 1)[..., None], -1)[..., 0]
    y1 = np.take_along_axis(y, k[..., None], -1)[..., 0]
    y2 = np.take_along_axis(y, (k + 1)[..., None], -1)[..., 0]
    denom = y0 - 2.0 * y1 + y2
    shift = np.where(denom > 0, 0.5 * (y0 - y2) / np.where(denom > 0, denom, 1.0), 0.0)
    out: FloatArray = x[k] + np.clip(shift, -1.0, 1.0) * (x[1] - x[0])
    return out


#: A pair's misfit grows with its rotation (a focal length or parallax a few percent off scales it): its robust
#: scale is at least this share of the rotation it measured.
RELATIVE_NOISE = 0.1


def robust_weights(residual: FloatArray, rotation: FloatArray) -> FloatArray:
    """Cauchy weights with a scale of 2.5 robust sigmas (at least 0.02 deg), or of :data:`RELATIVE_NOISE` of the
    pair's measured rotation where that is larger: when most pairs barely turn, the few that turn much (the
    ones that say most) are not taken for outliers for their larger misfit."""
    sigma = np.maximum(max(1.4826 * float(np.median(residual)), np.deg2rad(0.02)), RELATIVE_NOISE * rotation)
    out: FloatArray = 1.0 / (1.0 + (residual / (2.5 * sigma)) ** 2)
    return out


@dataclass(frozen=True)
class Solved:
    offset_s: float
    mount: FloatArray
    weights: FloatArray
    residual: FloatArray  # per pair at the solution (rad)
    fine: FloatArray  # fine offset grid around the solution
    fine_scatter: Scatter  # the pairs' products on it
    at_window_edge: bool  # the coarse search's best offset is at an end of its window
    bias: FloatArray  # (3,) the reference's rate bias (rad/s, link frame; zeros unless fitted)


def solve(orientations: Orientations, pairs: Pairs, opts: EgoMotionFitOptions) -> Solved:
    """Coarse grid, robust reweighting, a fine grid and a parabola, then the continuous minimum: offset and mount.

    The offset is a continuous unknown: forward kinematics is interpolated (slerp) at each frame's
    stamp plus the trial offset, and the last step minimises the misfit over the offset itself
    (bounded scalar search around the parabola's vertex), not over a grid of frame periods.
    """
    dt = pairs.dt if opts.rate_bias else None
    coarse = np.arange(-opts.max_offset_s, opts.max_offset_s + 0.5 * opts.step_s, opts.step_s)
    coarse_rv = link_rotvecs(orientations, pairs, coarse)
    coarse_scatter = Scatter(coarse_rv, pairs.rotvec, dt)
    weights = pairs.weight
    for _ in range(3):
        mounts, cost, _cross = coarse_scatter.fit(weights)
        best = int(np.argmin(cost))
        bias = coarse_scatter.bias(weights, mounts[best], best)
        residual = np.linalg.norm(pairs.rotvec - (coarse_rv[best] - bias * pairs.dt[:, None]) @ mounts[best], axis=1)
        weights = pairs.weight * robust_weights(residual, np.linalg.norm(pairs.rotvec, axis=1))
    coarse_cost = coarse_scatter.fit(weights)[1]
    best = int(np.argmin(coarse_cost))
    edge = best <= 1 or best >= coarse.size - 2
    half = max(3.0 * opts.step_s, 0.025)
    fine = float(coarse[best]) + np.arange(-half, half + 0.5 * opts.fine_step_s, opts.fine_step_s)
    fine_scatter = Scatter(link_rotvecs(orientations, pairs, fine), pairs.rotvec, dt)
    vertex = float(parabola_min(fine, fine_scatter.fit(weights)[1]))
    offset = (continuous_minimum(orientations, pairs, weights, dt, vertex, opts.fine_step_s) if opts.continuous
              else vertex)
    at = link_rotvecs(orientations, pairs, np.array([offset]))
    scatter = Scatter(at, pairs.rotvec, dt)
    mount = scatter.fit(weights)[0][0]
    bias = scatter.bias(weights, mount, 0)
    residual = np.linalg.norm(pairs.rotvec - (at[0] - bias * pairs.dt[:, None]) @ mount, axis=1)
    return Solved(offset_s=offset, mount=mount, weights=weights, residual=residual, fine=fine,
                   fine_scatter=fine_scatter, at_window_edge=edge, bias=bias)


def continuous_minimum(orientations: Orientations, pairs: Pairs, weights: FloatArray, dt: FloatArray | None,
                        start: float, step: float) -> float:
    """The offset minimising the weighted misfit within two fine steps of ``start`` (bounded Brent search)."""
    from scipy.optimize import minimize_scalar

    def cost(offset: float) -> float:
        scatter = Scatter(link_rotvecs(orientations, pairs, np.array([offset])), pairs.rotvec, dt)
        return float(scatter.fit(weights)[1][0])

    found = minimize_scalar(cost, bounds=(start - 2 * step, start + 2 * step), method="bounded",
                            options={"xatol": 1e-5})
    best = float(found.x)
    return best if cost(best) <= cost(start) else start


def link_fit(name: str, pairs: Pairs, solved: Solved, orientations: Orientations) -> LinkFit:
    w = solved.weights
    rms = float(np.sqrt((w * solved.residual**2).sum() / w.sum()))
    link_rv = link_rotvecs(orientations, pairs, np.array([solved.offset_s]))[0]
    return LinkFit(link=name, offset_s=solved.offset_s, q_link_cam=quat_of(solved.mount),
                   residual_deg=float(np.rad2deg(rms)),
                   link_rotation_deg=float(np.rad2deg(np.sqrt((link_rv**2).sum(1).mean()))), pairs=pairs.t0.size,
                   at_window_edge=solved.at_window_edge,
                   bias_rad_s=(float(solved.bias[0]), float(solved.bias[1]), float(solved.bias[2])))


#: Share of bootstrap minima at the fine grid's edge above which the offset is undetermined.
EDGE_SHARE = 0.05


def offset_undetermined(solved: Solved, boot: BlockBootstrap, opts: EgoMotionFitOptions) -> str:
    """Why the time offset cannot be trusted ("" when it can): its best value at an end of the search window
    (the true one may lie beyond), or resamples whose best lies at the edge of the grid around it (a flat
    or many-valleyed misfit)."""
    if solved.at_window_edge:
        return (f"its best value ({solved.offset_s * 1e3:+.0f} ms) lies at the edge of the +-{opts.max_offset_s:.2f} s "
                "search window, and the true offset may lie beyond it (evidence.camera_offset_window_s widens it)")
    if boot.at_edge > EDGE_SHARE:
        return f"{boot.at_edge:.0%} of the bootstrap minima lie at the edge of the search around it (a flat misfit)"
    return ""


@dataclass(frozen=True)
class BlockBootstrap:
    """Resamples of the offset and mount by :func:`block_bootstrap`, and how often a resample's best offset sat
    at the fine grid's edge."""

    offsets: FloatArray  # (B,)
    mounts: FloatArray  # (B, 3, 3)
    weights: FloatArray  # (B, N)
    at_edge: float  # share of resamples whose minimum is at the fine grid's edge


def block_bootstrap(pairs: Pairs, solved: Solved, opts: EgoMotionFitOptions) -> BlockBootstrap:
    """Block bootstrap over frame pairs (blocks of ``block_s`` of consecutive frames, by the first stamp: pairs
    that share frames are not independent) on the fine offset grid: each resample reweights the blocks and reads
    its offset and mount off the grid's products, nothing is refitted (unlike the fault models' bootstrap,
    :func:`framechain.analysis.fit.shares.refit_bootstrap`, which resamples observations and refits)."""
    rng = np.random.default_rng(opts.seed)
    block = np.floor((pairs.t0 - pairs.t0.min()) / opts.block_s).astype(np.int64)
    blocks = int(block.max()) + 1
    # Bayesian bootstrap (Rubin): each block weighed by an exponential draw, never left out. When the motion
    # is in a few blocks (a single pan at the end of a clip), a multinomial resample drops them all one time in
    # eight and its offset is then the still part's noise.
    counts = rng.exponential(1.0, size=(opts.bootstrap, blocks))  # (B, blocks)
    weights = counts[:, block] * solved.weights[None, :]
    _mounts, cost, cross = solved.fine_scatter.fit(weights)
    best = np.argmin(cost, axis=1)
    at_edge = float(np.mean((best == 0) | (best == solved.fine.size - 1)))
    offsets = parabola_min(solved.fine, cost)
    # Each resample's mount at its own offset: C interpolated between the grid points around it.
    where = np.clip((offsets - solved.fine[0]) / (solved.fine[1] - solved.fine[0]), 0, solved.fine.size - 1.001)
    k = where.astype(np.int64)
    alpha = (where - k)[:, None, None]
    rows = np.arange(opts.bootstrap)
    mounts = kabsch((1.0 - alpha) * cross[rows, k] + alpha * cross[rows, k + 1])
    return BlockBootstrap(offsets=offsets, mounts=mounts, weights=weights, at_edge=at_edge)


@dataclass(frozen=True)
class Information:
    """How well the pairs pin the offset and each axis of the mount: standard errors from the misfit's
    curvature (the residual's RMS over the square root of the information each parameter gets).

    A time offset is seen through the change of the link's rotation when the pairs' times shift (its
    angular acceleration): ``J = d a / d offset``, information ``sum w |J|^2``. A mount rotation about an
    axis ``e`` moves each prediction by ``e x a``: only rotation of the link *across* ``e`` shows it,
    information ``sum of the other eigenvalues`` of ``sum w a a^T`` (link frame).
    """

    sigma_deg: float  # robust RMS misfit per pair
    offset_se_s: float
    axes: FloatArray  # (3, 3) columns: the link's principal rotation axes (link frame), most turned last
    axis_se_deg: FloatArray  # (3,) the mount's standard error about each
    across_deg: FloatArray  # (3,) the link's rotation across each axis (RMS per pair)
    turning_deg: float  # the link's rotation (RMS per pair)


def information(orientations: Orientations, pairs: Pairs, solved: Solved, link_rv: FloatArray) -> Information:
    w = solved.weights
    sigma = float(np.sqrt((w * solved.residual**2).sum() / max(w.sum(), 1e-12)))
    step = 0.005
    around = link_rotvecs(orientations, pairs, np.array([solved.offset_s - step, solved.offset_s + step]))
    slope = (around[1] - around[0]) / (2 * step)
    offset_info = float((w * (slope**2).sum(axis=1)).sum())
    total = max(float(w.sum()), 1e-12)
    axes, across_deg, turning_deg = principal_axes(np.einsum("n,ni,nj->ij", w, link_rv, link_rv), total)
    return Information(sigma_deg=float(np.rad2deg(sigma)),
                        offset_se_s=sigma / np.sqrt(offset_info) if offset_info > 0 else float("inf"),
                        axes=axes, axis_se_deg=np.rad2deg(sigma / (np.deg2rad(across_deg) * np.sqrt(total))),
                        across_deg=across_deg, turning_deg=turning_deg)


def principal_axes(scatter: FloatArray, weight: float) -> tuple[FloatArray, FloatArray, float]:
    """From the weighted scatter ``sum w a a^T`` of a link's rotation vectors (and ``sum w``): its principal rotation
    axes (columns, link frame, most turned last), its rotation across each and in all (deg RMS per pair)."""
    values, axes = np.linalg.eigh(scatter)
    across = np.maximum(values.sum() - values, 1e-18)
    total = max(weight, 1e-12)
    return axes, np.rad2deg(np.sqrt(across / total)), float(np.rad2deg(np.sqrt(max(values.sum(), 0.0) / total)))


def weak_axes(axes: FloatArray, across_deg: FloatArray, sigma_deg: float) -> tuple[tuple[float, float, float], ...]:
    """The axes (columns of ``axes``) the link turned across by less than :data:`OBSERVABLE_RATIO` times the misfit:
    the mount about them is not observable."""
    floor = OBSERVABLE_RATIO * sigma_deg
    return tuple((float(axes[0, j]), float(axes[1, j]), float(axes[2, j])) for j in range(3) if across_deg[j] < floor)


def complete_mount(mounts: FloatArray, declared: FloatArray, axis: FloatArray) -> FloatArray:
    """``mounts`` (..., 3, 3) ``R_link_cam`` turned about ``axis`` (link frame) to lie nearest ``declared``.

    A link that turns about ``axis`` alone fixes where the mount sends that axis and nothing of the
    mount's rotation about it: of that family of mounts, ``R_axis(theta) X``, the one nearest the
    declared mount is kept (theta maximises ``tr(R_axis(theta) X declared^T)``, in closed form).
    """
    u = axis / np.linalg.norm(axis)
    skew = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
    m = mounts @ declared.T
    along = np.einsum("i,...ij,j->...", u, m, u)
    theta = np.arctan2(np.einsum("ij,...ji->...", skew, m), np.trace(m, axis1=-2, axis2=-1) - along)
    c, s_ = np.cos(theta)[..., None, None], np.sin(theta)[..., None, None]
    turn = c * np.eye(3) + s_ * skew + (1.0 - c) * np.outer(u, u)
    out: FloatArray = turn @ mounts
    return out


#: The link's rotation (RMS per pair), or its rotation across an axis, must be this many times the misfit left
#: for the offset, or the mount about that axis, to be seen. A real gimballed GoPro against its own gyro: 7.6
#: over the whole clip (a pan at its end), 2.4 over its still first half, 1.8 across the pan's axis.
OBSERVABLE_RATIO = 4.0


@dataclass(frozen=True)
class Observed:
    unobservable: str  # why nothing is ("" when the link turns enough)
    axes: tuple[tuple[float, float, float], ...]  # link-frame axes the mount is not observable about


#: Blocks of :attr:`EgoMotionFitOptions.block_s` the compared frame pairs must span: fewer leave the block bootstrap
#: next to nothing to resample (one block gives every resample the same offset and mount: an interval of width 0).
MIN_BLOCKS = 4


def too_short(pairs: Pairs, opts: EgoMotionFitOptions) -> str:
    """Why the compared frame pairs are too short a stretch for intervals ("" when they are not)."""
    span = float(pairs.t0.max() - pairs.t0.min()) if pairs.t0.size else 0.0
    if span >= (MIN_BLOCKS - 1) * opts.block_s:
        return ""
    return (f"the frame pairs it compares span {span:.2f} s (the episode less the offset search window "
            f"+-{opts.max_offset_s:.2f} s at each end), under the {(MIN_BLOCKS - 1) * opts.block_s:.1f} s its "
            "intervals need")


def observed(info: Information) -> Observed:
    """What the link's rotation lets the images show: nothing when it turns by less than
    :data:`OBSERVABLE_RATIO` times the misfit, else the mount about every axis it turns across that much."""
    floor = OBSERVABLE_RATIO * info.sigma_deg
    if info.turning_deg < floor:
        return Observed(f"its link turns {info.turning_deg:.3f} deg per frame pair, under {OBSERVABLE_RATIO:g} times "
                         f"the {info.sigma_deg:.3f} deg its images and forward kinematics disagree by", ())
    return Observed("", weak_axes(info.axes, info.across_deg, info.sigma_deg))


def focal_scale(pairs: Pairs, solved: Solved, link_rv: FloatArray, boot: BlockBootstrap) -> tuple[float, FloatArray]:
    """Measured over predicted rotation across the optical axis (x and y of the optical frame), and its bootstrap.

    A rotation about the optical x or y axis moves the image by ``f * angle``; measured with an
    assumed focal length ``f'`` it reads ``f / f'`` times the true angle. The scale and the mount
    are fitted in turn (a scaled measurement tilts a plain Kabsch fit).
    """
    weights = solved.weights
    scale, mount = 1.0, solved.mount
    num = den = np.zeros_like(weights)
    for _ in range(4):
        unscaled = pairs.rotvec * np.array([1.0 / scale, 1.0 / scale, 1.0])
        mount = kabsch(np.einsum("n,ni,nj->ij", weights, link_rv, unscaled))
        predicted = (link_rv @ mount)[:, :2]
        num = (predicted * pairs.rotvec[:, :2]).sum(axis=1)
        den = (predicted**2).sum(axis=1)
        if float(weights @ den) <= 0:
            return float("nan"), np.full(boot.offsets.size, np.nan)
        scale = float((weights @ num) / (weights @ den))
    ratio = (boot.weights @ num) / np.maximum(boot.weights @ den, 1e-18)
    return scale, ratio


def interval(values: FloatArray) -> tuple[float, float]:
    lo, hi = np.percentile(values, [2.5, 97.5])
    return float(lo), float(hi)


def mount_evidence(weights: FloatArray, link_rv: FloatArray, cam_rv: FloatArray, sigma_deg: float) -> MountEvidence:
    """The sums a mount fit rests on (:class:`MountEvidence`), for combining episodes."""
    return MountEvidence(cross=np.einsum("n,ni,nj->ij", weights, link_rv, cam_rv),
                         scatter=np.einsum("n,ni,nj->ij", weights, link_rv, link_rv), weight=float(weights.sum()),
                         sigma_deg=sigma_deg)
