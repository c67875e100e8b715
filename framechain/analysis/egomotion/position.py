"""A camera's position on its link, with its mount, focal length and time offset, from its matched features.

The rotation fit (:mod:`.fit`) measures each frame pair's rotation given the direction forward kinematics
moves the camera's centre, and so needs the camera's position on its link. A robot.yaml framechain
generates for a known arm cannot know it and puts the camera at its link's origin; a wrist camera a few
centimetres from there moves along another direction, its rotations are measured biased, and its
motion is not explained (generated SO-101 episodes, the camera 5.8 cm from ``gripper_link``: 17 deg/s of
misfit left, against 2 at its true position).

Here every matched pair of bearings is compared with the whole motion forward kinematics predicts from
the position ``xyz`` (metres, on the link), the mount rotation, the focal length's scale and the time
offset: the rotation between the two frames, and the direction the camera's centre moved, each match
free to lie at any positive depth along it (:func:`~framechain.vision.two_view.off_flow_residuals`, in
pixels). The link's own translation is in metres, so the directions alone fix the position in metres (a
camera at the link's origin and one 6 cm out move along different directions as the link turns). The
eight unknowns are fitted together by robust (Cauchy, 1 px) least squares from the rotation fit's mount
and offset and the declared position.

Measured on five generated SO-101 episodes (seeds 3, 5, 7 and 23, video 0 to 50 ms late, the camera at
(0.05, 0, -0.03) m with a 180 px focal length), started at the link's origin from the rotation-only fit's
mount and a guessed 160 px: the position came within 6 mm, the focal length within 3%, the mount within 1.5
deg, in 1 to 3 s each; every start offset from -100 to +100 ms reached the same fit. A second round on
the first one's inliers keeps wrong matches from pulling the position (10% of them, anywhere in the image,
had moved it 1.1 cm; near its epipolar line a wrong match passes any fixed pixel threshold, so the cut is
relative to the median residual).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from framechain.analysis.egomotion.model import LinkMotion
from framechain.analysis.egomotion.solve import Orientations
from framechain.arrays import BoolArray, FloatArray, IntArray
from framechain.geometry.rotations import quat_conjugate, quat_from_rotvec, quat_multiply, quat_rotate, quat_to_matrix
from framechain.vision.two_view import PairBatch, off_flow_residuals

__all__ = ["POSITION_LIMIT_M", "PositionFit", "fit_position"]

#: How far from its link's origin a camera may be fitted (metres, per axis): a camera on a link, not on another robot.
POSITION_LIMIT_M = 0.5
#: The focal length's scale is fitted within these factors of the one measured with (a guess from a field of view).
FOCAL_LIMITS = (0.5, 2.0)
#: Matches per frame pair the fit uses (drawn at random): the position needs many pairs, not every match of each.
MATCHES_PER_PAIR = 40
#: The robust scale of a match's residual (px): about the trackers' noise on 224x224 video.
RESIDUAL_SCALE_PX = 1.0
#: A match the first fit leaves further off than this (px), or this many times the median residual, is left out of
#: the second: a wrong match near its epipolar line passes any fixed threshold of pixels.
INLIER_PX = 3.0
INLIER_MEDIANS = 4.0
#: Frame pairs within this span (s) are taken to err together when the position's spread is estimated.
SPREAD_BLOCK_S = 0.5
#: A position whose spread (1 sd) exceeds this along some axis is not determined by the motion (m). On nine generated
#: SO-101 episodes the spread was 1.1 to 3.3 mm where the arm moved every joint (errors of 3 to 11 mm), 5.9 and 11.5
#: mm for motion a tenth as large and a 3 s episode (errors of 25 and 18 mm), and 0.87 and 11 m for an arm that only
#: panned or only rolled its wrist (errors of 23 and 43 cm); the errors reached 6 times the spread.
DETERMINED_M = 0.02
#: A camera fitted where it moves this share of its link origin's travel, or less, sits at a point the link turns
#: about (generated SO-101 episodes: 0.02 where only the wrist flexed and rolled, the fit 10 cm off along the line
#: through the axes' crossing with a spread of 0.7 mm; 1.0 to 4.1 where every joint moved).
STILL_TRAVEL = 0.25
#: A fitted unknown within this share of its search range from a limit is taken to have reached it.
AT_LIMIT_SHARE = 0.02


@dataclass(frozen=True)
class PositionFit:
    """The camera's position on ``link`` and what was fitted with it."""

    link: str
    xyz_link_cam: FloatArray  # (3,) metres, in the link's frame
    q_link_cam: FloatArray  # (4,) xyzw
    #: The focal length fitted over the one the matches were measured with.
    focal_factor: float
    offset_s: float
    #: The median match residual (px) at the start (the declared position) and fitted.
    residual_px: tuple[float, float]
    pairs: int
    matches: int
    #: Which unknowns ended at a limit of their search ("" when none): the fit is then not used.
    at_limit: str = ""
    #: The position's standard deviations along its principal axes (m, largest first), and those axes (rows, in the
    #: link's frame).
    spread_m: FloatArray = field(default_factory=lambda: np.full(3, np.nan))
    spread_axes: FloatArray = field(default_factory=lambda: np.eye(3))
    #: How far the camera's centre moves between its frames where fitted, over how far the link's origin does (median).
    travel_ratio: float = 1.0

    @property
    def undetermined(self) -> str:
        """Why the motion does not determine the position ("" when it does): an unknown at its limit, a spread over
        :data:`DETERMINED_M` (1 sd) along an axis, or a point the link turns about (moving :data:`STILL_TRAVEL` times
        as far as its origin, or less)."""
        if self.at_limit:
            return f"its {self.at_limit} reached the limit of the search"
        if not self.spread_m[0] <= DETERMINED_M:
            return ("this motion does not determine it (the link turned about too few axes, or too little, to tell "
                    "where along that axis it is)")
        if self.travel_ratio <= STILL_TRAVEL:
            return (f"it lies where the link turns about (moving {self.travel_ratio:.2f} times as far as the link's "
                    "origin): where along the line through that point the camera is, is not determined")
        return ""


@dataclass(frozen=True)
class _Matches:
    """The frame pairs' sampled matches: bearings (P, K, 3) in the optical frame, which of them are matches (the
    rest pad), and the frames' times (s from the link's first stamp)."""

    b0: FloatArray
    b1: FloatArray
    valid: BoolArray
    t0: FloatArray
    t1: FloatArray


def fit_position(
    batch: PairBatch, stamps0_ns: IntArray, stamps1_ns: IntArray, link: LinkMotion, *, q_link_cam: FloatArray,
    xyz_link_cam: FloatArray, offset_s: float, focal_px: float, max_offset_s: float, seed: int = 0,
) -> PositionFit | None:
    """The position, mount, focal scale and offset that best explain ``batch``'s matches by ``link``'s motion.

    ``batch`` holds the matched bearings measured with the focal length ``focal_px``, of frames stamped
    ``stamps0_ns`` and ``stamps1_ns``; the fit starts from ``q_link_cam``, ``xyz_link_cam`` and ``offset_s``,
    the offset searched within ``max_offset_s``. None when the link has no positions or no pair lies inside its
    span for every offset.
    """
    if link.xyz is None:
        return None
    from scipy.optimize import least_squares  # here: importing scipy.optimize costs every run 0.36 s

    origin = int(link.stamps_ns[0])
    orientations = Orientations(link, origin)
    matches = _sampled(batch, stamps0_ns, stamps1_ns, origin, orientations.times, max_offset_s, seed)
    if matches is None:
        return None
    centres = np.asarray(link.xyz, dtype=float)
    mount = np.asarray(q_link_cam, dtype=float) / np.linalg.norm(q_link_cam)
    kept = matches.valid  # the matches the fit rests on: all, then the inliers of the first fit

    def residuals(x: FloatArray) -> FloatArray:
        turn, xyz, log_focal, offset = x[:3], x[3:6], x[6], x[7]
        turned = quat_multiply(mount, quat_from_rotvec(turn))
        rotation, direction = _predicted(orientations, centres, turned, xyz, matches, offset)
        factor = float(np.exp(log_focal))
        scaled = PairBatch(_refocused(matches.b0, factor), _refocused(matches.b1, factor), matches.valid)
        # In pixels of the lens fitted: in radians, a longer focal length would shrink every residual.
        out: FloatArray = off_flow_residuals(scaled, rotation, direction) * (kept[..., None] * focal_px * factor)
        return out.ravel()

    start = np.r_[np.zeros(3), np.asarray(xyz_link_cam, dtype=float), 0.0, offset_s]
    limit = np.r_[np.full(3, np.inf), np.full(3, POSITION_LIMIT_M), np.log(FOCAL_LIMITS[1]), max_offset_s]
    lower = np.r_[-limit[:6], np.log(FOCAL_LIMITS[0]), -max_offset_s]
    start = np.clip(start, lower + 1e-9, limit - 1e-9)
    x = start
    # Wrong matches pull a robust fit too (10% of them: 1.1 cm on the position); fitted again on the first fit's
    # inliers, they do not.
    for last in (False, True):
        solved = least_squares(residuals, x, bounds=(lower, limit), loss="cauchy", f_scale=RESIDUAL_SCALE_PX,
                               x_scale=np.r_[np.full(3, 0.05), np.full(3, 0.02), 0.05, 0.01])
        x = solved.x
        if not last:
            size = np.linalg.norm(residuals(x).reshape(*kept.shape, 3), axis=-1)
            kept = matches.valid & (size < min(INLIER_PX, INLIER_MEDIANS * float(np.median(size[kept]))))
    spread = _position_spread(np.asarray(solved.jac), residuals(x), matches.t0)
    kept = used = matches.valid
    return PositionFit(
        link=link.link, xyz_link_cam=x[3:6].copy(), q_link_cam=quat_multiply(mount, quat_from_rotvec(x[:3])),
        focal_factor=float(np.exp(x[6])), offset_s=float(x[7]),
        residual_px=(_median_px(residuals(start), used), _median_px(residuals(x), used)),
        pairs=int(matches.t0.size), matches=int(used.sum()), at_limit=_at_limit(x, lower, limit), spread_m=spread[0],
        travel_ratio=_travel_ratio(orientations, centres, x[3:6], matches.t0 + x[7], matches.t1 + x[7]),
        spread_axes=spread[1])


def _at_limit(x: FloatArray, lower: FloatArray, upper: FloatArray) -> str:
    """The unknowns within :data:`AT_LIMIT_SHARE` of their search range from a limit, named ("" when none)."""
    span = np.where(np.isfinite(upper), upper - lower, 1.0)
    near = np.isfinite(upper) & ((x - lower < AT_LIMIT_SHARE * span) | (upper - x < AT_LIMIT_SHARE * span))
    names = ("", "", "", "x", "y", "z", "focal length", "offset")
    return ", ".join(name for name, hit in zip(names, near, strict=True) if hit and name)


def _position_spread(jacobian: FloatArray, residuals: FloatArray, pair_times: FloatArray
                     ) -> tuple[FloatArray, FloatArray]:
    """The position's standard deviations along its principal axes (m, largest first) and those axes (rows, in the
    link's frame), from the fit's Jacobian and residuals: a sandwich covariance whose middle sums the residuals'
    pulls over blocks of :data:`SPREAD_BLOCK_S` of frame pairs (pairs share frames and tracks, and a block's errors
    move together: counted as independent matches they would claim millimetres the motion cannot give)."""
    rows = jacobian.reshape(pair_times.size, -1, jacobian.shape[1])
    pulls = np.einsum("pkn,pk->pn", rows, residuals.reshape(pair_times.size, -1))
    block = np.floor((pair_times - pair_times.min()) / SPREAD_BLOCK_S).astype(np.int64)
    summed = np.zeros((int(block.max()) + 1, jacobian.shape[1]))
    np.add.at(summed, block, pulls)
    # The inverse of J^T J with its null directions kept (a pseudo-inverse would give them no spread at all), and the
    # plain covariance added: along a direction the matches do not see at all the sandwich's middle is zero too.
    values, vectors = np.linalg.eigh(jacobian.T @ jacobian)
    bread = (vectors / np.maximum(values, 1e-12 * max(float(values.max()), 1e-300))) @ vectors.T
    seen = np.count_nonzero(residuals)
    variance = float(residuals @ residuals) / max(seen * 2 / 3 - jacobian.shape[1], 1.0)  # 2 of 3 components free
    covariance = bread @ (summed.T @ summed) @ bread + variance * bread
    values, vectors = np.linalg.eigh(covariance[3:6, 3:6])
    order = np.argsort(values)[::-1]
    spread: FloatArray = np.sqrt(np.clip(values[order], 0.0, None))
    axes: FloatArray = vectors[:, order].T
    return spread, axes


def _sampled(batch: PairBatch, stamps0_ns: IntArray, stamps1_ns: IntArray, origin: int, times: FloatArray,
             max_offset_s: float, seed: int) -> _Matches | None:
    """At most :data:`MATCHES_PER_PAIR` matches of each pair whose frames stay inside the link's span for every
    offset searched."""
    t0: FloatArray = ((np.asarray(stamps0_ns, dtype=np.int64) - origin) * 1e-9).astype(np.float64)
    t1: FloatArray = ((np.asarray(stamps1_ns, dtype=np.int64) - origin) * 1e-9).astype(np.float64)
    inside = np.flatnonzero((t0 - max_offset_s >= times[0]) & (t1 + max_offset_s <= times[-1])
                            & (batch.valid.sum(axis=1) > 0))
    if inside.size == 0:
        return None
    valid = batch.valid[inside]
    # Valid matches first, in a random order, then the padding: the first K of each row are the sample.
    order = np.argsort(np.random.default_rng(seed).random(valid.shape) + (~valid) * 2.0, axis=1)
    order = order[:, :MATCHES_PER_PAIR]
    rows = inside[:, None]
    return _Matches(b0=batch.b0[rows, order], b1=batch.b1[rows, order],
                    valid=batch.valid[rows, order], t0=t0[inside], t1=t1[inside])


def _predicted(orientations: Orientations, centres: FloatArray, mount: FloatArray, xyz: FloatArray, matches: _Matches,
               offset: float) -> tuple[FloatArray, FloatArray]:
    """The camera's rotation ``R_cam0_cam1`` (P, 3, 3) and the unit direction its centre moved, in the earlier
    optical frame (P, 3), as the link's motion gives them with the camera at ``xyz`` turned by ``mount`` (xyzw)."""
    link0, link1, travel = _travel(orientations, centres, xyz, matches.t0 + offset, matches.t1 + offset)
    from_cam0 = quat_conjugate(quat_multiply(link0, mount))
    rotation = quat_to_matrix(quat_multiply(from_cam0, quat_multiply(link1, mount)))
    move = quat_rotate(from_cam0, travel).T
    direction: FloatArray = move / np.maximum(np.linalg.norm(move, axis=1, keepdims=True), 1e-12)
    return rotation, direction


def _travel(orientations: Orientations, centres: FloatArray, xyz: FloatArray, t0: FloatArray, t1: FloatArray
            ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The link's orientations at ``t0`` and ``t1`` (4, P) and how far a point at ``xyz`` on it moved between
    them, in the link's base (3, P)."""
    link0, link1 = orientations.at(t0), orientations.at(t1)  # components first
    times = orientations.times
    centre0 = np.stack([np.interp(t0, times, centres[:, i]) for i in range(3)]) + quat_rotate(link0, xyz)
    centre1 = np.stack([np.interp(t1, times, centres[:, i]) for i in range(3)]) + quat_rotate(link1, xyz)
    return link0, link1, centre1 - centre0


def _travel_ratio(orientations: Orientations, centres: FloatArray, xyz: FloatArray, t0: FloatArray, t1: FloatArray
                  ) -> float:
    """How far a point at ``xyz`` on the link moves between the frames, over how far its origin does (medians): a
    point the link turns about barely moves, and a camera placed there says nothing of where it is along the line
    through it."""
    moved = [float(np.median(np.linalg.norm(_travel(orientations, centres, at, t0, t1)[2], axis=0)))
             for at in (xyz, np.zeros(3))]
    return moved[0] / max(moved[1], 1e-12)


def _refocused(bearings: FloatArray, factor: float) -> FloatArray:
    """Unit bearings (..., 3) as a pinhole whose focal length is ``factor`` times longer sees the same pixels."""
    z = np.where(np.abs(bearings[..., 2]) > 1e-12, bearings[..., 2], 1e-12)
    rays = np.stack([bearings[..., 0] / (z * factor), bearings[..., 1] / (z * factor), np.ones_like(z)], axis=-1)
    out: FloatArray = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    return out


def _median_px(residuals: FloatArray, used: BoolArray) -> float:
    size = np.linalg.norm(residuals.reshape(*used.shape, 3), axis=-1)
    return float(np.median(size[used]))
