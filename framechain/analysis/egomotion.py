"""A camera's measured motion against forward kinematics: time offset, mount rotation, carrying link.

A camera on a link turns as its link turns. Between two frames stamped ``t0`` and ``t1`` the image
measures ``B = R_cam(t0)_cam(t1)`` (:class:`~framechain.timeline.EgoMotionTable`); forward kinematics
predicts the link's ``A = R_base_link(t0 + offset)^T R_base_link(t1 + offset)``, and with the mount
rotation ``X = R_link_cam``::

    B = X^T A X,   i.e.   rotvec(B) = X^T rotvec(A)

So for each trial ``offset_s`` the mount is a weighted Kabsch fit of the rotation axes (hand-eye
rotation), and the offset is the one that leaves the smallest misfit. Conventions as the fault
catalogue's latency: the pose that matches a frame stamped ``t`` is at ``t + offset_s``, so frames
late by ``d`` (showing the world ``d`` before their stamp) give ``offset_s = -d``.

A wrist camera over a table also translates, and near scenery moves with the translation: an
image-only rotation reads part of it as rotation (tens of percent at 0.3 m). So
:func:`fit_camera_motion` measures again with the translation direction forward kinematics
predicts (:func:`translation_prior`: the link's motion, the declared mount's position, the
current mount rotation and offset) and refits, a contraction towards the right values,
accelerated with Anderson mixing; three to five measurements usually settle it.

What each candidate link explains tells which link (which arm) the camera moves with. A link that
turns about one axis only leaves the mount's rotation about that axis unobservable; a camera that
does not turn (a fixed camera, a still arm) shows neither offset nor mount.

Intervals are 95% moving-block bootstrap intervals over the frame pairs (blocks of ``block_s``),
the mount's and offset's jointly (on synthetic rotations they hold the truth in about 85% of
episodes: a little narrow). When the intrinsics are not known, the ratio of measured to
predicted rotation across the optical axis is the ratio of true to assumed focal length.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from framechain.arrays import FloatArray, IntArray
from framechain.geometry.rotations import kabsch, quat_conjugate, quat_from_rotvec, quat_multiply, quat_to_rotvec
from framechain.timeline import EgoMotionTable, TranslationPrior

__all__ = [
    "EgoMotionFit",
    "EgoMotionFitOptions",
    "LinkFit",
    "LinkMotion",
    "Measure",
    "MountError",
    "RotationRates",
    "fit_camera_motion",
    "fit_link",
    "rotation_rates",
    "translation_prior",
]

#: Measures the camera's motion from its images, given a translation prior (None: rotation only).
Measure = Callable[[TranslationPrior | None], EgoMotionTable]


@dataclass(frozen=True)
class LinkMotion:
    """Forward kinematics of one candidate link: ``R_base_link`` at the robot state's stamps.

    ``base`` may be any frame fixed in the world (the arm's base): only rotations between two
    times of the same link are compared.
    """

    link: str
    stamps_ns: IntArray  # (T,) strictly increasing
    quat_xyzw: FloatArray  # (T, 4)
    xyz: FloatArray | None = None  # (T, 3) the link's origin in the base: for the translation prior


@dataclass(frozen=True)
class EgoMotionFitOptions:
    """Search range and resolution of the offset, bootstrap size, observability thresholds."""

    max_offset_s: float = 0.5
    step_s: float = 0.01
    fine_step_s: float = 0.0005
    bootstrap: int = 200
    block_s: float = 0.25
    #: Below this RMS rotation per frame pair (deg) the camera (or link) is taken as not turning.
    min_rotation_deg: float = 0.05
    #: The mount is observable about every axis when the rotation axes spread this much (ratio of the
    #: second to the first singular value of their scatter).
    min_axis_spread: float = 0.02
    #: Links whose misfit is within this factor of the best fit explain the motion as well.
    same_fit_ratio: float = 1.25
    min_pairs: int = 20
    #: Fit a constant rate bias of the reference too (a gyro's; forward kinematics has none).
    rate_bias: bool = False
    seed: int = 0


@dataclass(frozen=True)
class LinkFit:
    """The best offset and mount for one candidate link, and how well they explain the images."""

    link: str
    offset_s: float
    q_link_cam: FloatArray  # (4,) xyzw, R_link_cam
    residual_deg: float  # robust RMS misfit per frame pair
    link_rotation_deg: float  # RMS rotation of the link per frame pair (0: the link does not turn)
    pairs: int
    #: The best offset of the coarse search lies at an end of its window: the true one may lie beyond it.
    at_window_edge: bool = False
    #: The reference's rate bias fitted (rad/s, in the link's frame; zeros unless ``rate_bias``).
    bias_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class MountError:
    """The declared mount against the measured one: ``R_declared = R_measured exp(angle * axis)``.

    ``axis`` is a unit vector in the camera's optical frame; ``interval_deg`` the 95% interval of
    the angle.
    """

    angle_deg: float
    axis: tuple[float, float, float]
    interval_deg: tuple[float, float]


@dataclass(frozen=True)
class EgoMotionFit:
    """What the camera's own motion says about its time offset, mount and link."""

    camera: str
    link: str  # the link the camera moves with (best fit), "" when the camera does not turn
    declared_link: str
    #: Other candidates explaining the motion as well (links rigid with ``link``, or an ambiguous fit).
    alternatives: tuple[str, ...]
    links: tuple[LinkFit, ...]  # every candidate, best first
    offset_s: float
    offset_interval_s: tuple[float, float]
    q_link_cam: FloatArray  # measured R_link_cam on ``link``
    mount_error: MountError | None  # against the declared mount, when ``link`` is the declared link
    #: Measured over predicted rotation across the optical axis: true / assumed focal length.
    focal_scale: float
    focal_scale_interval: tuple[float, float]
    camera_rotation_deg: float  # RMS measured rotation per frame pair
    offset_observable: bool
    mount_observable: bool
    notes: tuple[str, ...]
    #: Why the offset is undetermined ("" when it is not): at the edge of its search window, a flat misfit.
    offset_undetermined: str = ""
    #: The reference's rate bias fitted (rad/s, link frame; zeros unless the options ask for it).
    bias_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def wrong_link(self) -> bool:
        """The camera moves with another link than the declared one (and not with it as well)."""
        return bool(self.link) and self.link != self.declared_link and self.declared_link not in self.alternatives


@dataclass(frozen=True)
class _Pairs:
    """The measured frame pairs used: times (s from the links' first stamp), rotation vectors, weights."""

    t0: FloatArray
    t1: FloatArray
    rotvec: FloatArray  # (N, 3) measured, optical frame
    weight: FloatArray

    @property
    def dt(self) -> FloatArray:
        out: FloatArray = self.t1 - self.t0
        return out


def _pairs(measured: EgoMotionTable, origin_ns: int, span_s: tuple[float, float], max_offset_s: float) -> _Pairs:
    """The pairs whose shifted times stay inside the links' span for every trial offset."""
    t0: FloatArray = (measured.stamp0_ns - origin_ns).astype(np.float64) * 1e-9
    t1: FloatArray = (measured.stamp1_ns - origin_ns).astype(np.float64) * 1e-9
    inside = (t0 - max_offset_s >= span_s[0]) & (t1 + max_offset_s <= span_s[1])
    inside &= np.isfinite(measured.quat_xyzw).all(axis=1)
    rotvec = Rotation.from_quat(measured.quat_xyzw[inside]).as_rotvec()
    return _Pairs(t0=t0[inside], t1=t1[inside], rotvec=rotvec, weight=np.ones(int(inside.sum())))


class _Orientations:
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


def _link_rotvecs(orientations: _Orientations, pairs: _Pairs, offsets: FloatArray) -> FloatArray:
    """The link's predicted rotation vectors ``rotvec(R(t0+d)^T R(t1+d))``, ``(G, N, 3)`` for G offsets."""
    first = orientations.at((pairs.t0[None, :] + offsets[:, None]).ravel())
    second = orientations.at((pairs.t1[None, :] + offsets[:, None]).ravel())
    out: FloatArray = quat_to_rotvec(quat_multiply(quat_conjugate(first), second)).T.reshape(offsets.size, -1, 3)
    return out


class _Scatter:
    """The products ``a b^T`` and ``|a|^2 + |b|^2`` of every pair at every trial offset, built once.

    ``link_rv`` (G, N, 3) are the link's rotation vectors at G offsets, ``cam_rv`` (N, 3) the measured
    ones; :meth:`fit` then weighs the pairs with one matrix product (BLAS), for one weight vector or
    a whole bootstrap at once. With ``dt`` (N,) the pairs' durations, a constant rate bias ``beta`` of the
    link's rotation is fitted too: ``a`` becomes ``a - beta dt``, alternating with the mount.
    """

    def __init__(self, link_rv: FloatArray, cam_rv: FloatArray, dt: FloatArray | None = None) -> None:
        g, n = link_rv.shape[:2]
        self.offsets = g
        self.outer = np.einsum("gni,nj->ngij", link_rv, cam_rv).reshape(n, g * 9)
        self.norms = ((link_rv**2).sum(-1) + (cam_rv**2).sum(-1)[None]).T  # (N, G)
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


def _parabola_min(x: FloatArray, y: FloatArray) -> FloatArray:
    """Sub-grid minimum along the last axis of ``y`` over the even grid ``x`` (a parabola through three points)."""
    k = np.clip(np.argmin(y, axis=-1), 1, x.size - 2)
    y0 = np.take_along_axis(y, (k - 1)[..., None], -1)[..., 0]
    y1 = np.take_along_axis(y, k[..., None], -1)[..., 0]
    y2 = np.take_along_axis(y, (k + 1)[..., None], -1)[..., 0]
    denom = y0 - 2.0 * y1 + y2
    shift = np.where(denom > 0, 0.5 * (y0 - y2) / np.where(denom > 0, denom, 1.0), 0.0)
    out: FloatArray = x[k] + np.clip(shift, -1.0, 1.0) * (x[1] - x[0])
    return out


def _robust_weights(residual: FloatArray) -> FloatArray:
    """Cauchy weights with a scale of 2.5 robust sigmas (at least 0.02 deg)."""
    sigma = max(1.4826 * float(np.median(residual)), np.deg2rad(0.02))
    out: FloatArray = 1.0 / (1.0 + (residual / (2.5 * sigma)) ** 2)
    return out


@dataclass(frozen=True)
class _Solved:
    offset_s: float
    mount: FloatArray
    weights: FloatArray
    residual: FloatArray  # per pair at the solution (rad)
    fine: FloatArray  # fine offset grid around the solution
    fine_scatter: _Scatter  # the pairs' products on it
    at_window_edge: bool  # the coarse search's best offset is at an end of its window
    bias: FloatArray  # (3,) the reference's rate bias (rad/s, link frame; zeros unless fitted)


def _solve(orientations: _Orientations, pairs: _Pairs, opts: EgoMotionFitOptions) -> _Solved:
    """Coarse grid, robust reweighting, a fine grid and a parabola, then the continuous minimum: offset and mount.

    The offset is a continuous unknown: forward kinematics is interpolated (slerp) at each frame's
    stamp plus the trial offset, and the last step minimises the misfit over the offset itself
    (bounded scalar search around the parabola's vertex), not over a grid of frame periods.
    """
    dt = pairs.dt if opts.rate_bias else None
    coarse = np.arange(-opts.max_offset_s, opts.max_offset_s + 0.5 * opts.step_s, opts.step_s)
    coarse_rv = _link_rotvecs(orientations, pairs, coarse)
    coarse_scatter = _Scatter(coarse_rv, pairs.rotvec, dt)
    weights = pairs.weight
    for _ in range(3):
        mounts, cost, _cross = coarse_scatter.fit(weights)
        best = int(np.argmin(cost))
        bias = coarse_scatter.bias(weights, mounts[best], best)
        residual = np.linalg.norm(pairs.rotvec - (coarse_rv[best] - bias * pairs.dt[:, None]) @ mounts[best], axis=1)
        weights = pairs.weight * _robust_weights(residual)
    coarse_cost = coarse_scatter.fit(weights)[1]
    best = int(np.argmin(coarse_cost))
    edge = best <= 1 or best >= coarse.size - 2
    half = max(3.0 * opts.step_s, 0.025)
    fine = float(coarse[best]) + np.arange(-half, half + 0.5 * opts.fine_step_s, opts.fine_step_s)
    fine_scatter = _Scatter(_link_rotvecs(orientations, pairs, fine), pairs.rotvec, dt)
    vertex = float(_parabola_min(fine, fine_scatter.fit(weights)[1]))
    offset = _continuous_minimum(orientations, pairs, weights, dt, vertex, opts.fine_step_s)
    at = _link_rotvecs(orientations, pairs, np.array([offset]))
    scatter = _Scatter(at, pairs.rotvec, dt)
    mount = scatter.fit(weights)[0][0]
    bias = scatter.bias(weights, mount, 0)
    residual = np.linalg.norm(pairs.rotvec - (at[0] - bias * pairs.dt[:, None]) @ mount, axis=1)
    return _Solved(offset_s=offset, mount=mount, weights=weights, residual=residual, fine=fine,
                   fine_scatter=fine_scatter, at_window_edge=edge, bias=bias)


def _continuous_minimum(orientations: _Orientations, pairs: _Pairs, weights: FloatArray, dt: FloatArray | None,
                        start: float, step: float) -> float:
    """The offset minimising the weighted misfit within two fine steps of ``start`` (bounded Brent search)."""
    from scipy.optimize import minimize_scalar

    def cost(offset: float) -> float:
        scatter = _Scatter(_link_rotvecs(orientations, pairs, np.array([offset])), pairs.rotvec, dt)
        return float(scatter.fit(weights)[1][0])

    found = minimize_scalar(cost, bounds=(start - 2 * step, start + 2 * step), method="bounded",
                            options={"xatol": 1e-5})
    best = float(found.x)
    return best if cost(best) <= cost(start) else start


def fit_link(
    measured: EgoMotionTable, link: LinkMotion, options: EgoMotionFitOptions | None = None
) -> LinkFit | None:
    """The offset and mount that best explain the measured motion by ``link``'s; None with too few pairs."""
    opts = options or EgoMotionFitOptions()
    origin = int(link.stamps_ns[0])
    span = (0.0, (int(link.stamps_ns[-1]) - origin) * 1e-9)
    pairs = _pairs(measured, origin, span, opts.max_offset_s)
    if pairs.t0.size < opts.min_pairs:
        return None
    orientations = _Orientations(link, origin)
    return _link_fit(link.link, pairs, _solve(orientations, pairs, opts), orientations)


def _link_fit(name: str, pairs: _Pairs, solved: _Solved, orientations: _Orientations) -> LinkFit:
    w = solved.weights
    rms = float(np.sqrt((w * solved.residual**2).sum() / w.sum()))
    link_rv = _link_rotvecs(orientations, pairs, np.array([solved.offset_s]))[0]
    return LinkFit(link=name, offset_s=solved.offset_s, q_link_cam=Rotation.from_matrix(solved.mount).as_quat(),
                   residual_deg=float(np.rad2deg(rms)),
                   link_rotation_deg=float(np.rad2deg(np.sqrt((link_rv**2).sum(1).mean()))), pairs=pairs.t0.size,
                   at_window_edge=solved.at_window_edge,
                   bias_rad_s=(float(solved.bias[0]), float(solved.bias[1]), float(solved.bias[2])))


def translation_prior(
    link: LinkMotion, q_link_cam: FloatArray, xyz_link_cam: FloatArray, offset_s: float
) -> TranslationPrior:
    """The camera's translation direction FK predicts between two frame stamps, in the earlier optical frame.

    The camera centre is ``p_link(t) + R_link(t) xyz_link_cam`` at ``t = stamp + offset_s``; rows
    outside the link's span (or without link positions) are NaN.
    """
    if link.xyz is None:
        raise ValueError(f"link {link.link!r}: no positions for a translation prior")
    origin = int(link.stamps_ns[0])
    orientations = _Orientations(link, origin)
    times = orientations.times
    rot = Rotation.from_quat(np.asarray(link.quat_xyzw, dtype=float))
    centres = np.asarray(link.xyz, dtype=float) + rot.apply(np.asarray(xyz_link_cam, dtype=float))
    mount = Rotation.from_quat(np.asarray(q_link_cam, dtype=float))

    def prior(stamp0_ns: IntArray, stamp1_ns: IntArray) -> FloatArray:
        t0 = (np.asarray(stamp0_ns, dtype=np.int64) - origin) * 1e-9 + offset_s
        t1 = (np.asarray(stamp1_ns, dtype=np.int64) - origin) * 1e-9 + offset_s
        inside = (t0 >= times[0]) & (t1 <= times[-1])
        out = np.full((t0.size, 3), np.nan)
        if not inside.any():
            return out
        c0 = np.stack([np.interp(t0[inside], times, centres[:, i]) for i in range(3)], axis=1)
        c1 = np.stack([np.interp(t1[inside], times, centres[:, i]) for i in range(3)], axis=1)
        cam0 = Rotation.from_quat(orientations.at(t0[inside]).T) * mount
        move = cam0.inv().apply(c1 - c0)
        norm = np.linalg.norm(move, axis=1, keepdims=True)
        out[inside] = np.where(norm > 1e-9, move / np.maximum(norm, 1e-12), np.nan)
        return out

    return prior


@dataclass(frozen=True)
class RotationRates:
    """A camera's rotation between frame pairs, measured and as a link's forward kinematics predicts it.

    Rates (rad/s) are rotation vectors in the camera's optical frame over the pair's time; the
    prediction is the link's rotation between the pair's stamps shifted by ``offset_s``, carried into
    the camera by the mount (NaN outside the link's span). The measured rates are corrected for a focal
    scale (measured over true rotation across the optical axis).
    """

    stamp0_ns: IntArray
    stamp1_ns: IntArray
    measured: FloatArray  # (N, 3)
    predicted: FloatArray  # (N, 3)

    @property
    def residual(self) -> FloatArray:
        """``|measured - predicted|`` per pair (rad/s; NaN where nothing is predicted)."""
        out: FloatArray = np.linalg.norm(self.measured - self.predicted, axis=1)
        return out


def rotation_rates(
    measured: EgoMotionTable, link: LinkMotion, q_link_cam: FloatArray, offset_s: float, *, focal_scale: float = 1.0
) -> RotationRates:
    """The measured pairs of ``measured`` against ``link`` carrying the camera by the mount ``q_link_cam``."""
    origin = int(link.stamps_ns[0])
    orientations = _Orientations(link, origin)
    t0: FloatArray = ((measured.stamp0_ns - origin) * 1e-9).astype(np.float64)
    t1: FloatArray = ((measured.stamp1_ns - origin) * 1e-9).astype(np.float64)
    dt = t1 - t0
    camera = Rotation.from_quat(measured.quat_xyzw).as_rotvec() if len(measured) else np.zeros((0, 3))
    camera = camera * np.array([1.0 / focal_scale, 1.0 / focal_scale, 1.0])
    pairs = _Pairs(t0=t0, t1=t1, rotvec=camera, weight=np.ones(t0.size))
    link_rv = _link_rotvecs(orientations, pairs, np.array([offset_s]))[0]
    inside = (t0 + offset_s >= orientations.times[0]) & (t1 + offset_s <= orientations.times[-1])
    predicted = np.where(inside[:, None], link_rv @ Rotation.from_quat(q_link_cam).as_matrix(), np.nan)
    return RotationRates(stamp0_ns=measured.stamp0_ns, stamp1_ns=measured.stamp1_ns, measured=camera / dt[:, None],
                         predicted=predicted / dt[:, None])


def fit_camera_motion(
    measure: Measure,
    links: Sequence[LinkMotion],
    *,
    camera: str,
    declared_link: str,
    declared_q_link_cam: FloatArray,
    declared_xyz_link_cam: FloatArray | None = None,
    refinements: int = 5,
    options: EgoMotionFitOptions | None = None,
) -> EgoMotionFit:
    """Offset, mount and carrying link of a camera from its measured motion against the candidate links' FK.

    ``measure(prior)`` measures the camera's motion (:func:`framechain.adapters.messages.egomotion.
    measure_egomotion` with the camera's tracks). Rotation-only first, to see whether the camera
    turns at all and to rank the candidates; the declared link is kept when it fits about as well
    as the best. Then up to ``refinements`` times with the translation forward kinematics predicts
    for that link under the current mount and offset, starting from the declared mount (near
    scenery moves with the camera's translation, which a rotation-only measurement reads as
    rotation). The candidates are ranked again on the final measurement; when another link fits
    clearly better there, it is refined instead.
    """
    opts = options or EgoMotionFitOptions()
    table = measure(None)
    notes: list[str] = []
    turning = _rms_deg(Rotation.from_quat(table.quat_xyzw).as_rotvec()) if len(table) else 0.0
    if turning < opts.min_rotation_deg:
        notes.append(f"camera {camera} does not turn ({turning:.3f} deg RMS per frame pair): a fixed camera or a "
                     "still arm; its time offset, mount and link are not observable from its images")
        return _unobservable(camera, declared_link, turning, notes)
    ranked = _rank(table, links, opts)
    if not ranked:
        notes.append(f"camera {camera}: fewer than {opts.min_pairs} measured frame pairs inside the links' span")
        return _unobservable(camera, declared_link, turning, notes)
    declared = _Start(np.asarray(declared_q_link_cam, dtype=float), 0.0,
                      np.zeros(3) if declared_xyz_link_cam is None else np.asarray(declared_xyz_link_cam, dtype=float))
    by_name = {link.link: link for link in links}
    first = (table, ranked)
    candidates: list[str] = []
    if declared_link in _similar(ranked, ranked[0], opts):
        table, fit, ranked = _refined(measure, by_name[declared_link], [declared], first, links, refinements, opts)
        if ranked[0].link != declared_link and ranked[0].residual_deg * opts.same_fit_ratio < fit.residual_deg:
            notes.append(f"camera {camera}: measured with {declared_link}'s translation, its motion fits "
                         f"{ranked[0].link} better; refined on the links that fit best")
            candidates = [f.link for f in ranked if f.link != declared_link][:_MAX_CANDIDATES]
    else:
        candidates = list(_similar(ranked, ranked[0], opts))[:_MAX_CANDIDATES]
    if candidates:
        # Each candidate from the declared mount (the same link on another arm) and from its rotation-only
        # fit (another link); the one its own refined measurement fits best wins.
        tried = [_refined(measure, by_name[name], [declared, _Start(f.q_link_cam, f.offset_s, np.zeros(3))],
                          first, links, refinements, opts)
                 for name in candidates for f in first[1] if f.link == name]
        table, fit, ranked = min(tried, key=lambda item: item[1].residual_deg)
    link = by_name[fit.link]
    similar = _similar(ranked, next((f for f in ranked if f.link == fit.link), fit), opts)
    return _final(table, link, fit, ranked, similar, declared_link, np.asarray(declared_q_link_cam, dtype=float),
                  camera, turning, notes, opts)


#: At most this many candidate links are refined when the declared one does not fit.
_MAX_CANDIDATES = 3


@dataclass(frozen=True)
class _Start:
    """Where a refinement starts: mount rotation (xyzw), offset (s), the camera's position on the link (m)."""

    q_link_cam: FloatArray
    offset_s: float
    xyz: FloatArray


def _refined(
    measure: Measure, link: LinkMotion, starts: Sequence[_Start], first: tuple[EgoMotionTable, list[LinkFit]],
    links: Sequence[LinkMotion], refinements: int, opts: EgoMotionFitOptions,
) -> tuple[EgoMotionTable, LinkFit, list[LinkFit]]:
    """The link's fit on a measurement made with its own translation prior, and every candidate ranked on it.

    With several starts, two refinements from each pick the one to finish from. Without link positions
    (or refinements) the rotation-only fit stands.
    """
    own = next(f for f in first[1] if f.link == link.link)
    if link.xyz is None or refinements <= 0:
        return first[0], own, first[1]
    trials = [(*_refine_with_translation(measure, link, (s.q_link_cam, s.offset_s), s.xyz,
                                         min(2, refinements), opts), s) for s in starts]
    table, fit, start = min(trials, key=lambda item: item[1].residual_deg)
    if refinements > 2:
        table, fit = _refine_with_translation(measure, link, (fit.q_link_cam, fit.offset_s), start.xyz,
                                              refinements - 2, opts)
    return table, fit, _rank(table, links, opts)


def _rank(table: EgoMotionTable, links: Sequence[LinkMotion], opts: EgoMotionFitOptions) -> list[LinkFit]:
    """Every candidate's best fit to the measured motion, best first."""
    return sorted((f for f in (fit_link(table, link, opts) for link in links) if f is not None),
                  key=lambda f: f.residual_deg)


def _similar(ranked: list[LinkFit], reference: LinkFit, opts: EgoMotionFitOptions) -> tuple[str, ...]:
    """The links that explain the motion about as well as ``reference`` (within ``same_fit_ratio``)."""
    best = min(reference.residual_deg, ranked[0].residual_deg)
    return tuple(f.link for f in ranked if f.residual_deg <= best * opts.same_fit_ratio)


#: Offset (s) to radians in the refinement's state vector: 10 ms weighs as 1 degree.
_OFFSET_WEIGHT = np.deg2rad(1.0) / 0.010


def _refine_with_translation(
    measure: Measure, link: LinkMotion, start: tuple[FloatArray, float], xyz: FloatArray, refinements: int,
    opts: EgoMotionFitOptions,
) -> tuple[EgoMotionTable, LinkFit]:
    """Measure with the translation FK predicts under the current mount and offset, refit, repeat.

    The mount and offset a measurement returns depend on the prior it was given (a prior a few
    degrees off leaves a share of its error in the rotations): a contraction towards the right
    values, accelerated with Anderson mixing of the last three iterates (state: the mount's
    rotation vector relative to the start, and the offset with 10 ms weighing as one degree).
    """
    base = Rotation.from_quat(start[0])
    state = np.r_[0.0, 0.0, 0.0, start[1] * _OFFSET_WEIGHT]
    inputs: list[FloatArray] = []
    outputs: list[FloatArray] = []
    table, fit = EgoMotionTable.empty(), None
    for _ in range(refinements):
        mount = (base * Rotation.from_rotvec(state[:3])).as_quat()
        table = measure(translation_prior(link, mount, xyz, float(state[3] / _OFFSET_WEIGHT)))
        fit = fit_link(table, link, opts)
        if fit is None:
            break
        result = np.r_[(base.inv() * Rotation.from_quat(fit.q_link_cam)).as_rotvec(), fit.offset_s * _OFFSET_WEIGHT]
        if outputs and float(np.abs(result - outputs[-1]).max()) < np.deg2rad(0.02):
            break
        inputs.append(state)
        outputs.append(result)
        state = _anderson(inputs[-3:], outputs[-3:])
    if fit is None:
        raise ValueError(f"link {link.link!r}: too few measured frame pairs with a translation prior")
    return table, fit


def _anderson(inputs: list[FloatArray], outputs: list[FloatArray]) -> FloatArray:
    """The next iterate of a fixed-point map from its last few inputs and outputs (Anderson type II)."""
    if len(inputs) == 1:
        return outputs[0]
    residuals = np.array([g - x for x, g in zip(inputs, outputs, strict=True)]).T
    images = np.array(outputs).T
    gamma = np.linalg.lstsq(np.diff(residuals, axis=1), residuals[:, -1], rcond=None)[0]
    out: FloatArray = images[:, -1] - np.diff(images, axis=1) @ gamma
    return out


def _rms_deg(rotvec: FloatArray) -> float:
    return float(np.rad2deg(np.sqrt((rotvec**2).sum(axis=1).mean()))) if rotvec.size else 0.0


def _unobservable(camera: str, declared_link: str, turning: float, notes: list[str]) -> EgoMotionFit:
    nan2 = (float("nan"), float("nan"))
    return EgoMotionFit(
        camera=camera, link="", declared_link=declared_link, alternatives=(), links=(), offset_s=float("nan"),
        offset_interval_s=nan2, q_link_cam=np.full(4, np.nan), mount_error=None, focal_scale=float("nan"),
        focal_scale_interval=nan2, camera_rotation_deg=turning, offset_observable=False, mount_observable=False,
        notes=tuple(notes),
    )


def _final(
    table: EgoMotionTable, link: LinkMotion, fit: LinkFit, ranked: list[LinkFit], similar: tuple[str, ...],
    declared_link: str, declared_q: FloatArray, camera: str, turning: float, notes: list[str],
    opts: EgoMotionFitOptions,
) -> EgoMotionFit:
    """Intervals by bootstrap on the final measurement, observability, the mount against the declared one."""
    origin = int(link.stamps_ns[0])
    span = (0.0, (int(link.stamps_ns[-1]) - origin) * 1e-9)
    pairs = _pairs(table, origin, span, opts.max_offset_s)
    orientations = _Orientations(link, origin)
    solved = _solve(orientations, pairs, opts)
    boot = _bootstrap(pairs, solved, opts)
    mount = Rotation.from_matrix(solved.mount)
    link_rv = _link_rotvecs(orientations, pairs, np.array([solved.offset_s]))[0] - solved.bias * pairs.dt[:, None]
    spread = _axis_spread(link_rv, solved.weights)
    mount_observable = spread >= opts.min_axis_spread
    if not mount_observable:
        notes.append(f"link {link.link} turned about one axis only (spread {spread:.3f}): the camera's mount "
                     "rotation about that axis is not observable")
    undetermined = _offset_undetermined(solved, boot, opts)
    if undetermined:
        notes.append(f"time offset of camera {camera} is undetermined: {undetermined}")
    focal, focal_boot = _focal_scale(pairs, solved, link_rv, boot)
    error = None
    if link.link == declared_link:
        wrong = mount.inv() * Rotation.from_quat(declared_q)
        angles = np.rad2deg((Rotation.from_matrix(boot.mounts).inv() * Rotation.from_quat(declared_q)).magnitude())
        rotvec = wrong.as_rotvec()
        angle = float(np.linalg.norm(rotvec))
        axis = rotvec / angle if angle > 0 else np.array([0.0, 0.0, 1.0])
        error = MountError(angle_deg=float(np.rad2deg(angle)), axis=(float(axis[0]), float(axis[1]), float(axis[2])),
                           interval_deg=_interval(angles))
    elif link.link not in similar or declared_link not in similar:
        notes.append(f"camera {camera} moves with {link.link}, not with the declared {declared_link}")
    links = (_chosen_fit(fit, solved, pairs, orientations), *[f for f in ranked if f.link != link.link])
    return EgoMotionFit(
        camera=camera, link=link.link, declared_link=declared_link,
        alternatives=tuple(name for name in similar if name != link.link), links=links,
        offset_s=solved.offset_s, offset_interval_s=_interval(boot.offsets),
        q_link_cam=mount.as_quat(), mount_error=error, focal_scale=focal, focal_scale_interval=_interval(focal_boot),
        camera_rotation_deg=turning, offset_observable=not undetermined, mount_observable=mount_observable,
        notes=tuple(notes), offset_undetermined=undetermined,
        bias_rad_s=(float(solved.bias[0]), float(solved.bias[1]), float(solved.bias[2])),
    )


#: Share of bootstrap minima at the fine grid's edge above which the offset is undetermined.
_EDGE_SHARE = 0.05


def _offset_undetermined(solved: _Solved, boot: _Boot, opts: EgoMotionFitOptions) -> str:
    """Why the time offset cannot be trusted ("" when it can): its best value at an end of the search window
    (the true one may lie beyond), or resamples whose best lies at the edge of the grid around it (a flat
    or many-valleyed misfit)."""
    if solved.at_window_edge:
        return (f"its best value ({solved.offset_s * 1e3:+.0f} ms) lies at the edge of the +-{opts.max_offset_s:.2f} s "
                "search window, and the true offset may lie beyond it")
    if boot.at_edge > _EDGE_SHARE:
        return f"{boot.at_edge:.0%} of the bootstrap minima lie at the edge of the search around it (a flat misfit)"
    return ""


def _chosen_fit(fit: LinkFit, solved: _Solved, pairs: _Pairs, orientations: _Orientations) -> LinkFit:
    """The chosen link's fit as measured with its translation prior."""
    return _link_fit(fit.link, pairs, solved, orientations)


@dataclass(frozen=True)
class _Boot:
    offsets: FloatArray  # (B,)
    mounts: FloatArray  # (B, 3, 3)
    weights: FloatArray  # (B, N)
    at_edge: float  # share of resamples whose minimum is at the fine grid's edge


def _bootstrap(pairs: _Pairs, solved: _Solved, opts: EgoMotionFitOptions) -> _Boot:
    """Block bootstrap over frame pairs (blocks of ``block_s`` by the first stamp) on the fine offset grid."""
    rng = np.random.default_rng(opts.seed)
    block = np.floor((pairs.t0 - pairs.t0.min()) / opts.block_s).astype(np.int64)
    blocks = int(block.max()) + 1
    draws = rng.integers(0, blocks, size=(opts.bootstrap, blocks))
    counts = np.stack([np.bincount(row, minlength=blocks) for row in draws])  # (B, blocks)
    weights = counts[:, block] * solved.weights[None, :]
    _mounts, cost, cross = solved.fine_scatter.fit(weights)
    best = np.argmin(cost, axis=1)
    at_edge = float(np.mean((best == 0) | (best == solved.fine.size - 1)))
    offsets = _parabola_min(solved.fine, cost)
    # Each resample's mount at its own offset: C interpolated between the grid points around it.
    where = np.clip((offsets - solved.fine[0]) / (solved.fine[1] - solved.fine[0]), 0, solved.fine.size - 1.001)
    k = where.astype(np.int64)
    alpha = (where - k)[:, None, None]
    rows = np.arange(opts.bootstrap)
    mounts = kabsch((1.0 - alpha) * cross[rows, k] + alpha * cross[rows, k + 1])
    return _Boot(offsets=offsets, mounts=mounts, weights=weights, at_edge=at_edge)


def _axis_spread(link_rv: FloatArray, weights: FloatArray) -> float:
    """Second over first singular value of the weighted scatter of the link's rotation vectors."""
    scatter = np.einsum("n,ni,nj->ij", weights, link_rv, link_rv)
    values = np.linalg.eigvalsh(scatter)
    return float(np.sqrt(max(values[1], 0.0) / values[2])) if values[2] > 0 else 0.0


def _focal_scale(pairs: _Pairs, solved: _Solved, link_rv: FloatArray, boot: _Boot) -> tuple[float, FloatArray]:
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


def _interval(values: FloatArray) -> tuple[float, float]:
    lo, hi = np.percentile(values, [2.5, 97.5])
    return float(lo), float(hi)
