"""The time offset of a camera measured with the translation forward kinematics predicts: one unknown, used twice.

A wrist camera's images move with its rotation and its translation; on small frames the two are nearly
interchangeable, so the rotation is measured given the translation direction forward kinematics
predicts between the two frames (:func:`framechain.analysis.egomotion.translation_prior`). That
prediction depends on the time offset too. Measuring with the prior of one offset and then fitting the
offset freely against forward kinematics does not give back the true offset: the measured rotation
leans towards the prior's timing (on a generated episode a prior 20 ms late moved the free fit by 7 ms,
and iterating such fits settled a third of the way from the start to the truth). So the offset is
treated as one unknown: for each trial offset ``d``, the motion is measured with the prior at ``d`` and
compared with forward kinematics at ``d`` (the mount fitted, robust weights), and the offset is the
``d`` whose measurement fits best. Found by bracketing and a parabola, then on a grid of offsets around
it, whose costs give the bootstrap intervals (:func:`framechain.analysis.egomotion.solve.block_bootstrap`).

Each measurement costs one pass over the tracks (tens of milliseconds for an episode), so what moves
smoothly is not measured at every trial: the grid's measurements are interpolated (quadratic in the
offset) from three made at its centre and ends, and the mount search's are linear in the mount's turn,
from one measurement a step about each axis. On a generated two-camera episode the prior moved the
measurement by 0.06 deg RMS per pair across a grid (24 ms), and the interpolation stayed within 0.003 deg
of measuring again; the misfit per pair is about 0.04 deg.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from framechain.analysis.egomotion.model import EgoMotionFitOptions, LinkMotion, Measure
from framechain.analysis.egomotion.solve import (
    OBSERVABLE_RATIO,
    Orientations,
    Pairs,
    Scatter,
    Solved,
    complete_mount,
    frame_pairs,
    link_rotvecs,
    parabola_min,
    principal_axes,
    robust_weights,
    weak_axes,
)
from framechain.arrays import BoolArray, FloatArray, IntArray
from framechain.geometry.rotations import Inverse, Rotations, RotationVector, matrix_of, quat_of, rotvec_of
from framechain.timeline import EgoMotionTable, TranslationPrior

__all__ = ["Joint", "Searched", "finish_fit", "search_offset"]

#: Steps (s) of the bracketing search, of the grid the intervals are measured on, and its half-width in steps.
BRACKET_STEP_S = 0.02
GRID_STEP_S = 0.004
GRID_HALF = 3

#: Makes the translation prior of a link, mount rotation (xyzw), camera position on the link (m) and offset (s).
PriorOf = Callable[[LinkMotion, FloatArray, FloatArray, float], TranslationPrior]


@dataclass(frozen=True)
class Joint:
    """The offset and mount that fit best with the measurement made at that offset, and what they rest on."""

    solved: Solved  # its ``fine`` grid: trial offsets around the optimum, each with its own (interpolated) measurement
    pairs: Pairs  # the pairs measured at the optimum (rotation vectors of that measurement)
    table: EgoMotionTable  # the measurement at the optimum
    residual_deg: float  # robust RMS misfit per pair at the optimum


class _Trials:
    """Measurements at trial offsets (cached), each compared with forward kinematics at its own offset."""

    def __init__(self, measure: Measure, link: LinkMotion, prior_of: PriorOf, q_link_cam: FloatArray,
                 xyz: FloatArray, opts: EgoMotionFitOptions) -> None:
        self.measure, self.link, self.prior_of, self.xyz, self.opts = measure, link, prior_of, xyz, opts
        self.q_link_cam = np.asarray(q_link_cam, dtype=float)
        self.origin = int(link.stamps_ns[0])
        self.span = (0.0, (int(link.stamps_ns[-1]) - self.origin) * 1e-9)
        self.orientations = Orientations(link, self.origin)
        self.tables: dict[float, EgoMotionTable] = {}
        self.costs: dict[float, float] = {}
        self.between: dict[tuple[float, float, float], tuple[Pairs, float]] = {}  # (offset, span): interpolated

    def table(self, offset: float) -> EgoMotionTable:
        """The rotations measured with the prior at ``offset`` (rows and rotations alone: what trials compare)."""
        key = round(offset, 6)
        if key not in self.tables:
            self.tables[key] = self._measured(self.q_link_cam, key, rotations_only=True)
        return self.tables[key]

    def complete(self, offset: float) -> EgoMotionTable:
        """The whole measurement with the prior at ``offset`` (translation directions, residuals and parallax too),
        its rotations those of :meth:`table` (which it stands in for from now on)."""
        key = round(offset, 6)
        self.tables[key] = self._measured(self.q_link_cam, key, rotations_only=False)
        return self.tables[key]

    def _measured(self, q_link_cam: FloatArray, offset: float, *, rotations_only: bool) -> EgoMotionTable:
        return self.measure(self.prior_of(self.link, q_link_cam, self.xyz, offset), rotations_only=rotations_only)

    def pairs(self, table: EgoMotionTable) -> Pairs:
        """The pairs of ``table`` that stay inside the link's span for every trial offset (the same for every trial)."""
        return frame_pairs(table, self.origin, self.span, self.opts.max_offset_s)

    def cost(self, offset: float) -> float:
        """Robust RMS misfit (rad) of the measurement at ``offset`` against forward kinematics at ``offset``."""
        key = round(offset, 6)
        if key not in self.costs:
            self.costs[key] = _fixed_offset_fit(self.pairs(self.table(key)), self.orientations, key)[0]
        return self.costs[key]

    def interpolated(self, offset: float, span: tuple[float, float]) -> tuple[Pairs, float]:
        """The measurement at ``offset`` (inside ``span``, a grid's first and last offsets) and its cost: interpolated,
        quadratic in the offset, between the measurements at the span's ends and middle (the pairs all three
        measured); measured when the span is one offset (a grid clipped to the search window's end)."""
        low, high = span
        key = (round(offset, 6), round(low, 6), round(high, 6))
        if key not in self.between:
            if high - low < 1e-9:
                pairs = self.pairs(self.table(low))
            else:
                anchors = np.array([low, 0.5 * (low + high), high])
                middle = self.pairs(self.table(float(anchors[1])))
                rotvecs = np.stack([_rotvecs_of(self.pairs(self.table(float(a))), middle) for a in anchors])  # (3,N,3)
                lagrange = np.array([np.prod([(offset - anchors[j]) / (anchors[i] - anchors[j])
                                              for j in range(3) if j != i]) for i in range(3)])
                rotvec = np.tensordot(lagrange, rotvecs, axes=1)
                ok = np.flatnonzero(np.isfinite(rotvec).all(axis=1))
                pairs = replace(_take(middle, ok), rotvec=rotvec[ok])
            self.between[key] = (pairs, _fixed_offset_fit(pairs, self.orientations, offset)[0])
        return self.between[key]

    def turned(self, offset: float) -> Callable[[FloatArray], Pairs]:
        """The measurement at ``offset`` with the mount in use turned by a rotation vector (rad, after the mount):
        linear in the turn, from the measurement with the mount in use and turned MOUNT_STEP_DEG about each axis."""
        base = self.q_link_cam
        h = np.deg2rad(MOUNT_STEP_DEG)
        middle = self.pairs(self.table(offset))
        steps = [self.pairs(self._measured(quat_of((base, RotationVector(h * axis))), round(offset, 6),
                                           rotations_only=True)) for axis in np.eye(3)]
        slopes = np.stack([(_rotvecs_of(step, middle) - middle.rotvec) / h for step in steps])  # (3, N, 3) per rad
        ok = np.isfinite(slopes).all(axis=(0, 2))
        kept, slopes = _take(middle, np.flatnonzero(ok)), slopes[:, ok]

        def at(turn: FloatArray) -> Pairs:
            return replace(kept, rotvec=kept.rotvec + np.tensordot(turn, slopes, axes=1))

        return at

    def mount_costs(self, offset: float, focal_scale: float) -> Callable[[FloatArray], float]:
        """The joint cost at ``offset`` of the mount turned by a rotation vector (rad, after the mount in use), that
        mount used for the prior (:meth:`turned`) and the comparison alike (no mount fitted), the measured rotation
        across the optical axis taken as ``focal_scale`` times the true one (so that a wrong focal length is not
        made up for by tilting the mount)."""
        base = self.q_link_cam
        measured = self.turned(offset)
        unturned = measured(np.zeros(3))
        link_rv = link_rotvecs(self.orientations, unturned, np.array([offset]))[0]
        unscale = np.array([1.0 / focal_scale, 1.0 / focal_scale, 1.0])

        def cost(turn: FloatArray) -> float:
            pairs = measured(turn)
            if pairs.t0.size == 0:
                return float("inf")
            residual = np.linalg.norm(pairs.rotvec * unscale - link_rv @ matrix_of((base, RotationVector(turn))),
                                      axis=1)
            weights = pairs.weight * robust_weights(residual, np.linalg.norm(pairs.rotvec, axis=1))
            return float(np.sqrt((weights * residual**2).sum() / weights.sum()))

        return cost

    def focal_scale(self, offset: float) -> float:
        """Measured over predicted rotation across the optical axis at ``offset`` with the mount fitted there."""
        _cost, mount, weights, pairs = _fixed_offset_fit(self.pairs(self.table(offset)), self.orientations, offset)
        if pairs.t0.size == 0:
            return 1.0
        predicted = (link_rotvecs(self.orientations, pairs, np.array([offset]))[0] @ mount)[:, :2]
        den = float(weights @ (predicted**2).sum(axis=1))
        return float(weights @ (predicted * pairs.rotvec[:, :2]).sum(axis=1)) / den if den > 0 else 1.0

    def fitted_mount(self, offset: float) -> FloatArray:
        """The mount (matrix) fitted to the measurement at ``offset`` against forward kinematics at ``offset``; about
        an axis the link did not turn across (:meth:`weak_axis`), the mount in use (Kabsch would take that turn from
        the last bits of the arithmetic, and the fixed point of :func:`_remount` with it: 170 deg apart between two
        sums of the same products in another order, on an arm that only pans)."""
        cost, mount, weights, pairs = _fixed_offset_fit(self.pairs(self.table(offset)), self.orientations, offset)
        axis = self.weak_axis(offset, cost, weights, pairs)
        return mount if axis is None else complete_mount(mount, matrix_of(self.q_link_cam), axis)

    def weak_axis(self, offset: float, cost: float, weights: FloatArray, pairs: Pairs) -> FloatArray | None:
        """The link-frame axis the link turned across by less than the misfit ``cost`` (rad) itself, None when there
        is none, or more than one (a link that barely turns: nothing of the mount is seen). Not the final fit's test
        (:func:`~framechain.analysis.egomotion.solve.weak_axes`, OBSERVABLE_RATIO times its misfit): at a trial
        offset the misfit can be five times the final one (a generated episode with its mount 10 deg off: 0.64 against
        0.13 deg, its link turned 2.3 deg across its least axis), while an arm that only pans turns 0.000 across its
        axis, against 0.126."""
        if pairs.t0.size == 0 or not np.isfinite(cost):
            return None
        link_rv = link_rotvecs(self.orientations, pairs, np.array([offset]))[0]
        axes, across, _turning = principal_axes(np.einsum("n,ni,nj->ij", weights, link_rv, link_rv),
                                                float(weights.sum()))
        weak = weak_axes(axes, across, float(np.rad2deg(cost)) / OBSERVABLE_RATIO)
        return np.asarray(weak[0]) if len(weak) == 1 else None

    def use_mount(self, mount: Rotations) -> None:
        """Measure from now on with the translation prior of ``mount``."""
        self.q_link_cam = quat_of(mount)
        self.tables.clear()
        self.costs.clear()
        self.between.clear()


def _fixed_offset_fit(pairs: Pairs, orientations: Orientations, offset: float
                      ) -> tuple[float, FloatArray, FloatArray, Pairs]:
    """Cost (robust RMS, rad), mount, robust weights and pairs of ``pairs`` against the link at ``offset``."""
    if pairs.t0.size == 0:
        return float("inf"), np.eye(3), np.zeros(0), pairs
    link_rv = link_rotvecs(orientations, pairs, np.array([offset]))
    scatter = Scatter(link_rv, pairs.rotvec)
    weights = pairs.weight
    magnitude = np.linalg.norm(pairs.rotvec, axis=1)
    for _ in range(3):
        mount = scatter.fit(weights)[0][0]
        residual = np.linalg.norm(pairs.rotvec - link_rv[0] @ mount, axis=1)
        weights = pairs.weight * robust_weights(residual, magnitude)
    mount = scatter.fit(weights)[0][0]
    residual = np.linalg.norm(pairs.rotvec - link_rv[0] @ mount, axis=1)
    return float(np.sqrt((weights * residual**2).sum() / weights.sum())), mount, weights, pairs


def _search(trials: _Trials, starts: list[float], limit: float) -> float:
    """Near the offset of least cost: the best start, then a bracket walked in steps of BRACKET_STEP_S and one
    parabola through it (the grid of :func:`_grid` finishes it). Starts beyond the +-``limit`` window are taken at its
    edge (a rotation-only offset can lie up to the ranking's fine grid past it)."""
    best = min((float(np.clip(s, -limit, limit)) for s in starts), key=trials.cost)
    step = BRACKET_STEP_S
    left, right = max(best - step, -limit), min(best + step, limit)
    while trials.cost(left) < trials.cost(best) and left > -limit:
        best, left = left, max(left - step, -limit)
    while trials.cost(right) < trials.cost(best) and right < limit:
        best, right = right, min(right + step, limit)
    grid = np.array([left, best, right])
    costs = np.array([trials.cost(float(x)) for x in grid])
    return float(np.clip(parabola_min(grid, costs[None])[0], -limit, limit))


def _grid(trials: _Trials, centre: float, limit: float) -> tuple[FloatArray, float]:
    """Trial offsets GRID_STEP_S apart around ``centre`` with the least cost inside them (moved out to three times
    when it lies at an end), and the parabola's vertex there. Each offset's measurement is interpolated across the
    grid (:meth:`_Trials.interpolated`)."""
    grid = _grid_at(centre, limit)
    for _ in range(3):
        costs = np.array([trials.interpolated(float(x), (grid[0], grid[-1]))[1] for x in grid])
        k = int(np.argmin(costs))
        if 0 < k < grid.size - 1 or abs(grid[k]) >= limit - 1e-9:
            break
        grid = _grid_at(float(grid[GRID_HALF]) + (k - GRID_HALF) * GRID_STEP_S, limit)
    costs = np.array([trials.interpolated(float(x), (grid[0], grid[-1]))[1] for x in grid])
    return grid, float(parabola_min(grid, costs[None])[0])


def _grid_at(centre: float, limit: float) -> FloatArray:
    """Offsets GRID_STEP_S apart around ``centre``, the whole grid moved inside the +-``limit`` window where it would
    cross it (not clipped: offsets piled on the window's edge leave the grid no spacing to fit a parabola or a
    resample's offset on)."""
    steps = GRID_STEP_S * np.arange(-GRID_HALF, GRID_HALF + 1, dtype=np.float64)
    if steps[-1] - steps[0] >= 2.0 * limit:
        return np.linspace(-limit, limit, steps.size)
    out: FloatArray = np.clip(np.clip(centre, -limit - steps[0], limit - steps[-1]) + steps, -limit, limit)
    return out


#: The mount is measured again (and the offset searched near where it was) at most this many times, until it
#: moves by less than REMOUNT_DEG: the prior's direction in the camera depends on the mount, and a measurement
#: with the prior of one mount returns a mount only part of the way to the one its images show (about two
#: thirds of the way on generated episodes), so the iterates are mixed (Anderson) to reach the fixed point.
REMOUNTS = 4
REMOUNT_DEG = 0.2


def _remount(trials: _Trials, best: float) -> None:
    """The mount's fixed point at offset ``best``: each measurement's fitted mount fed back into its prior."""
    base = trials.q_link_cam
    inputs: list[FloatArray] = []
    outputs: list[FloatArray] = []
    state = np.zeros(3)
    for _ in range(REMOUNTS):
        result = rotvec_of((Inverse(base), trials.fitted_mount(best)))
        if np.rad2deg(np.linalg.norm(result - state)) < REMOUNT_DEG:
            break
        inputs.append(state)
        outputs.append(result)
        state = anderson(inputs[-3:], outputs[-3:])
        trials.use_mount((base, RotationVector(state)))


#: Step (deg) of the joint search of the mount about each axis.
MOUNT_STEP_DEG = 1.0
#: The mount is searched only on measurements whose implied focal length is within this of the one used: a focal
#: length clearly off distorts the measured rotation more than a scale can say, and the caller measures again.
FOCAL_SETTLED = 0.05


def _mount_search(trials: _Trials, best: float) -> None:
    """The mount of least joint cost near the fixed point: a parabola along each of three axes through steps of
    MOUNT_STEP_DEG, one step of their vertices taken when it lowers the cost (a measurement leans towards its
    prior's mount as towards its prior's offset, so the fixed point is near, not at, the best mount)."""
    scale = trials.focal_scale(best)
    if abs(scale - 1.0) > FOCAL_SETTLED:  # measured again with the focal length it implies first (run.py)
        return
    cost = trials.mount_costs(best, scale)
    centre = cost(np.zeros(3))
    h = np.deg2rad(MOUNT_STEP_DEG)
    step = np.zeros(3)
    for k in range(3):
        minus, plus = (cost(np.eye(3)[k] * sign * h) for sign in (-1.0, 1.0))
        curvature = minus - 2.0 * centre + plus
        if curvature > 0:
            step[k] = float(np.clip(0.5 * (minus - plus) / curvature, -2.0, 2.0)) * h
    # Nothing is learnt about an axis the link did not turn across: the step keeps the mount about it.
    cost_now, _mount, weights, pairs = _fixed_offset_fit(trials.pairs(trials.table(best)), trials.orientations, best)
    weak = trials.weak_axis(best, cost_now, weights, pairs)
    if weak is not None:
        axis = matrix_of(trials.q_link_cam).T @ weak  # the mount's turns are after it: about camera-frame axes
        step = step - (step @ axis) * axis
    if cost(step) < centre:
        trials.use_mount((trials.q_link_cam, RotationVector(step)))


def anderson(inputs: list[FloatArray], outputs: list[FloatArray]) -> FloatArray:
    """The next iterate of a fixed-point map from its last few inputs and outputs (Anderson type II)."""
    if len(inputs) == 1:
        return outputs[0]
    residuals = np.array([g - x for x, g in zip(inputs, outputs, strict=True)]).T
    images = np.array(outputs).T
    gamma = np.linalg.lstsq(np.diff(residuals, axis=1), residuals[:, -1], rcond=None)[0]
    out: FloatArray = images[:, -1] - np.diff(images, axis=1) @ gamma
    return out


@dataclass(frozen=True)
class Searched:
    """A link's offset search (:func:`search_offset`), for :func:`finish_fit` to finish: its trials, the offset found
    and the misfit there (deg per pair, with the mount's fixed point)."""

    trials: _Trials
    offset_s: float
    misfit_deg: float


def search_offset(measure: Measure, link: LinkMotion, prior_of: PriorOf, mounts: list[FloatArray], xyz: FloatArray,
                  starts: list[float], opts: EgoMotionFitOptions) -> Searched | None:
    """The offset and mount of ``link`` measured jointly (module text), first part: the better of ``mounts`` (xyzw)
    at the first of ``starts`` (s), the offset searched from the best start, and the mount's fixed point there (about
    a third of the measurements). Its misfit is within a factor of two of the finished fit's (on generated episodes
    with the video 0.3 s late and the mount 25 deg off the search alone was 15 times above it). None when no pair
    stays inside the link's span."""
    candidates = [_Trials(measure, link, prior_of, q, xyz, opts) for q in mounts]
    trials = min(candidates, key=lambda t: t.cost(starts[0]))
    best = _search(trials, starts, opts.max_offset_s)
    if not np.isfinite(trials.cost(best)):
        return None
    _remount(trials, best)  # the grid that follows is centred here: its middle measurement is this one
    cost = trials.cost(best)
    return Searched(trials, best, float(np.rad2deg(cost))) if np.isfinite(cost) else None


def finish_fit(searched: Searched) -> Joint | None:
    """The joint fit from its offset search (:func:`search_offset`): the grid, the mount search, the grid again and
    the optimum with its interval grid. None when too few pairs stay inside the link's span."""
    trials, best = searched.trials, searched.offset_s
    opts = trials.opts
    limit = opts.max_offset_s
    best = _grid(trials, best, limit)[1]
    _mount_search(trials, best)
    grid, best = _grid(trials, best, limit)
    table = trials.complete(best)
    cost, mount, weights, pairs = _fixed_offset_fit(trials.pairs(table), trials.orientations, best)
    if pairs.t0.size < opts.min_pairs:
        return None
    solved = _grid_solved(trials, grid, pairs, weights, best, mount)
    return Joint(solved=solved, pairs=pairs, table=table, residual_deg=float(np.rad2deg(cost)))


def _grid_solved(trials: _Trials, grid: FloatArray, pairs: Pairs, weights: FloatArray, best: float,
                 mount: FloatArray) -> Solved:
    """The optimum as the bootstrap takes it: the grid's offsets, each with its own (interpolated) measurement of
    the same pairs."""
    rotvecs = np.stack([_rotvecs_of(trials.interpolated(float(x), (grid[0], grid[-1]))[0], pairs)
                        for x in grid])  # (G, N, 3)
    usable: BoolArray = np.asarray(np.isfinite(rotvecs).all(axis=(0, 2)), dtype=bool)
    rotvecs = np.where(usable[None, :, None], rotvecs, 0.0)
    link_rv = link_rotvecs(trials.orientations, pairs, grid)
    scatter = Scatter(link_rv, rotvecs)
    w = weights * usable
    residual = np.linalg.norm(pairs.rotvec - link_rotvecs(trials.orientations, pairs, np.array([best]))[0] @ mount,
                              axis=1)
    edge = abs(best) >= trials.opts.max_offset_s - trials.opts.step_s
    return Solved(offset_s=best, mount=mount, weights=w, residual=residual, fine=grid, fine_scatter=scatter,
                  at_window_edge=edge, bias=np.zeros(3))


def _take(pairs: Pairs, rows: IntArray) -> Pairs:
    return Pairs(t0=pairs.t0[rows], t1=pairs.t1[rows], rotvec=pairs.rotvec[rows], weight=pairs.weight[rows])


def _rotvecs_of(source: Pairs, pairs: Pairs) -> FloatArray:
    """The rotation vectors ``source`` has for the pairs of ``pairs`` (matched by their times; NaN: none)."""
    mine = np.stack([source.t0, source.t1], axis=1)
    wanted = np.stack([pairs.t0, pairs.t1], axis=1)
    keys, codes = np.unique(np.concatenate([mine, wanted]), axis=0, return_inverse=True)
    codes = codes.reshape(-1)
    row_of_key = np.full(keys.shape[0], -1, dtype=np.int64)
    row_of_key[codes[: len(mine)]] = np.arange(len(mine))
    rows = row_of_key[codes[len(mine):]]
    out = np.full((pairs.t0.size, 3), np.nan)
    found = rows >= 0
    out[found] = source.rotvec[rows[found]]
    return out
