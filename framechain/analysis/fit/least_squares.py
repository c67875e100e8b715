"""Fitting fault models to evidence: a grid for time offsets, then scipy least squares.

An :class:`Objective` turns a Perturbation into residuals (N, 3) in metres against the evidence
(logged points, a target, a reference, or the centroid of a static target). Model choice uses
BIC with a noise floor, so that the simplest explanation wins unless a richer one is clearly
better, and the posterior weights of the candidates give each choice a confidence.

Time offsets are searched over the model's whole range (+-1 s) before any local fit: on real
logs the error against the offset has several dips (periodic motion) and a narrow one far from
zero is common (a stamp offset of half a second). The coarse grid runs on a subsample of the
observations, its best few dips are refined on a fine grid over all of them, and least squares
starts from the best.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from framechain.analysis.model.chain import ChainInputs, Perturbation
from framechain.analysis.model.fault import FaultModel
from framechain.arrays import FloatArray, IntArray


class Objective(Protocol):
    """Residuals (N, 3) of a perturbed chain against the evidence; NaN where it cannot be evaluated."""

    def __call__(self, inputs: ChainInputs, pert: Perturbation, /) -> FloatArray: ...

    def take(self, index: IntArray, /) -> Objective:
        """The objective over a subset of the observations (same order as ``inputs.take``)."""
        ...

#: Noise floor (m) in the BIC: below a millimetre per axis, better fits mean nothing.
NOISE_FLOOR_M = 1e-3
#: Residual of an observation the perturbed chain cannot evaluate (its pose is out of span).
MISSING_RESIDUAL_M = 1.0
#: Step of the coarse offset grid (s): finer than the narrowest dip of a latency (a motion of a
#: few hertz gives dips some 50 ms wide).
COARSE_STEP_S = 0.01
#: Step of the fine grid around each coarse dip (s), over +-COARSE_STEP_S.
FINE_STEP_S = 0.0005
#: Observations the coarse grid is evaluated on (evenly spaced in the inputs' order), and the fine one.
GRID_SUBSAMPLE = 800
FINE_SUBSAMPLE = 4000
#: Coarse dips refined on the fine grid.
GRID_DIPS = 3
#: A grid offset at which fewer than this share of the observations can be evaluated is not tried.
MIN_EVALUABLE_SHARE = 0.5


@dataclass(frozen=True)
class Fit:
    """Fitted parameters of a set of models, with the residual statistics and BIC."""

    models: tuple[FaultModel, ...]
    params: tuple[FloatArray, ...]
    rss: float
    n_residuals: int
    bic: float
    distances: FloatArray  # (N,) |residual| per observation

    def perturbation(self, base: Perturbation | None = None) -> Perturbation:
        pert = base or Perturbation()
        for model, x in zip(self.models, self.params, strict=True):
            pert = model.apply(pert, x)
        return pert


def perturbation_of(models: Sequence[FaultModel], x: FloatArray, base: Perturbation | None = None) -> Perturbation:
    pert = base or Perturbation()
    k = 0
    for model in models:
        pert = model.apply(pert, x[k : k + model.n_params])
        k += model.n_params
    return pert


def _residual_vector(objective: Objective, inputs: ChainInputs, pert: Perturbation) -> FloatArray:
    r = objective(inputs, pert)
    r = np.where(np.isfinite(r), r, MISSING_RESIDUAL_M)
    return r.reshape(-1)


def bic(rss: float, n: int, k: int, penalty: float = 0.0) -> float:
    """Bayesian information criterion with a noise floor on the residual variance."""
    return float(n * np.log(rss / max(n, 1) + NOISE_FLOOR_M**2) + k * np.log(max(n, 2)) + 2.0 * penalty)


def fit_models(
    models: Sequence[FaultModel],
    objective: Objective,
    inputs: ChainInputs,
    *,
    base: Perturbation | None = None,
    x_start: FloatArray | None = None,
    grid: bool = True,
) -> Fit:
    """Fit the parameters of ``models`` jointly (multi-start; offsets from a grid first)."""
    models = tuple(models)
    k = sum(m.n_params for m in models)
    penalty = sum(m.choice_penalty for m in models)
    if k == 0:
        x = np.zeros(0)
        return _finish(models, x, objective, inputs, base, penalty)
    lower = np.concatenate([m.lower for m in models])
    upper = np.concatenate([m.upper for m in models])
    scale = np.concatenate([m.x_scale for m in models])
    starts = [np.concatenate([m.x0 for m in models]) if x_start is None else np.asarray(x_start, dtype=float)]
    if x_start is None:
        offset = 0
        for m in models:  # vary one model's start at a time
            for alt in m.starts:
                s = starts[0].copy()
                s[offset : offset + m.n_params] = alt
                starts.append(s)
            offset += m.n_params
    if grid and x_start is None:
        starts = [_grid_offsets(models, s, objective, inputs, base) for s in starts]

    ridge = np.concatenate([np.full(m.n_params, m.ridge) for m in models])
    origin = np.concatenate([m.x0 for m in models])
    pulled = bool(np.any(ridge > 0))

    def fun(x: FloatArray) -> FloatArray:
        residual = _residual_vector(objective, inputs, perturbation_of(models, x, base))
        return np.concatenate([residual, ridge * (x - origin)]) if pulled else residual

    from scipy.optimize import least_squares  # here: a run measured only on camera motion never fits a fault model

    best: tuple[float, FloatArray] | None = None
    for start in starts:
        result = least_squares(
            fun,
            np.clip(start, lower, upper),
            bounds=(lower, upper),
            x_scale=scale,
            method="trf",
            max_nfev=200,
            xtol=1e-10,
            ftol=1e-10,
        )
        cost = float(2.0 * result.cost)
        if best is None or cost < best[0]:
            best = (cost, result.x)
    assert best is not None
    return _finish(models, best[1], objective, inputs, base, penalty)


def _grid_offsets(
    models: tuple[FaultModel, ...],
    start: FloatArray,
    objective: Objective,
    inputs: ChainInputs,
    base: Perturbation | None,
) -> FloatArray:
    """Replace every time-offset start by the best value of a coarse-then-fine grid (others held)."""
    x = start.copy()
    coarse_objective, coarse_inputs = subsample(objective, inputs, GRID_SUBSAMPLE)
    fine_objective, fine_inputs = subsample(objective, inputs, FINE_SUBSAMPLE)
    offset = 0
    for m in models:
        if m.fault.value == "latency":
            lo, hi = float(m.lower[0]), float(m.upper[0])
            coarse = np.arange(lo, hi + 1e-9, COARSE_STEP_S)
            costs = _grid_costs(models, x, offset, coarse, coarse_objective, coarse_inputs, base)
            best_value, best_cost = float(x[offset]), np.inf
            for centre in _dips(coarse, costs, GRID_DIPS):
                fine = np.clip(np.arange(centre - COARSE_STEP_S, centre + COARSE_STEP_S + 1e-9, FINE_STEP_S), lo, hi)
                fine_costs = _grid_costs(models, x, offset, fine, fine_objective, fine_inputs, base)
                k = int(np.argmin(fine_costs))
                if fine_costs[k] < best_cost:
                    best_value, best_cost = float(fine[k]), float(fine_costs[k])
            x[offset] = best_value
        offset += m.n_params
    return x


def subsample(objective: Objective, inputs: ChainInputs, size: int) -> tuple[Objective, ChainInputs]:
    """At most ``size`` observations, evenly spaced (so every part of the log keeps some)."""
    n = len(inputs)
    if n <= size:
        return objective, inputs
    index = even_rows(n, size)
    return objective.take(index), inputs.take(index)


def even_rows(n: int, size: int) -> IntArray:
    """``size`` of ``n`` rows, evenly spaced from the first to the last (all of them when fewer)."""
    out: IntArray = np.unique(np.linspace(0, n - 1, min(size, n)).round().astype(np.int64))
    return out


def _grid_costs(
    models: tuple[FaultModel, ...],
    x: FloatArray,
    offset: int,
    values: FloatArray,
    objective: Objective,
    inputs: ChainInputs,
    base: Perturbation | None,
) -> FloatArray:
    """Mean squared residual over the observations evaluable at each value of one parameter.

    Observations the shifted pose cannot reach (past the ends of the odometry) are left out rather
    than penalised, so that a large true offset is not hidden by the log's ends; an offset that
    leaves too few evaluable is not tried (infinite cost).
    """
    trial = x.copy()
    costs = np.full(values.size, np.inf)
    n = max(len(inputs), 1)
    for i, value in enumerate(values):
        trial[offset] = value
        r = objective(inputs, perturbation_of(models, trial, base))
        finite = np.isfinite(r).all(axis=1)
        if finite.sum() >= MIN_EVALUABLE_SHARE * n and finite.any():
            costs[i] = float(np.mean(np.sum(r[finite] ** 2, axis=1)))
    return costs


def _dips(values: FloatArray, costs: FloatArray, count: int) -> list[float]:
    """The ``count`` lowest local minima of a grid curve (the global one first)."""
    finite = np.isfinite(costs)
    if not finite.any():
        return [0.0]
    padded = np.r_[np.inf, costs, np.inf]
    local = finite & (costs <= padded[:-2]) & (costs <= padded[2:])
    candidates = np.flatnonzero(local)
    order = candidates[np.argsort(costs[candidates], kind="stable")]
    return [float(values[k]) for k in order[:count]]


def _finish(
    models: tuple[FaultModel, ...],
    x: FloatArray,
    objective: Objective,
    inputs: ChainInputs,
    base: Perturbation | None,
    penalty: float,
) -> Fit:
    r = objective(inputs, perturbation_of(models, x, base))
    r = np.where(np.isfinite(r), r, MISSING_RESIDUAL_M)
    rss = float(np.sum(r * r))
    n = int(r.size)
    params = []
    offset = 0
    for m in models:
        params.append(np.asarray(x[offset : offset + m.n_params], dtype=float))
        offset += m.n_params
    k = sum(m.n_params for m in models)
    return Fit(
        models=models,
        params=tuple(params),
        rss=rss,
        n_residuals=n,
        bic=bic(rss, n, k, penalty),
        distances=np.linalg.norm(r, axis=1),
    )


def posterior_weights(bics: Sequence[float]) -> FloatArray:
    """Relative BIC weights exp(-BIC/2), normalised: the confidence among candidate explanations."""
    b = np.asarray(bics, dtype=float)
    w = np.exp(-(b - b.min()) / 2.0)
    out: FloatArray = w / w.sum()
    return out
