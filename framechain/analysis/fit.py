"""Fitting fault models to evidence: a coarse grid for time offsets, then scipy least squares.

An :class:`Objective` turns a Perturbation into residuals (N, 3) in metres against the evidence
(logged points, a target, a reference, or the centroid of a static target). Model choice uses
BIC with a noise floor, so that the simplest explanation wins unless a richer one is clearly
better, and the posterior weights of the candidates give each choice a confidence.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from framechain.analysis.chain_model import ChainInputs, Perturbation
from framechain.analysis.faults import FaultModel
from framechain.timeline.arrays import FloatArray

#: Residuals (N, 3) of a perturbed chain against the evidence; NaN where it cannot be evaluated.
Objective = Callable[[ChainInputs, Perturbation], FloatArray]

#: Noise floor (m) in the BIC: below a millimetre per axis, better fits mean nothing.
NOISE_FLOOR_M = 1e-3
#: Residual of an observation the perturbed chain cannot evaluate (its pose is out of span).
MISSING_RESIDUAL_M = 1.0
#: Grid of time offsets tried before the local refinement (s).
OFFSET_GRID_S = np.arange(-0.25, 0.2501, 0.0025)


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

    def fun(x: FloatArray) -> FloatArray:
        return _residual_vector(objective, inputs, perturbation_of(models, x, base))

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
    """Replace every time-offset start by the best value on a coarse grid (others held)."""
    x = start.copy()
    offset = 0
    for m in models:
        if m.fault.value == "latency":
            costs = []
            for value in OFFSET_GRID_S:
                x[offset] = value
                r = _residual_vector(objective, inputs, perturbation_of(models, x, base))
                costs.append(float(np.dot(r, r)))
            x[offset] = OFFSET_GRID_S[int(np.argmin(costs))]
        offset += m.n_params
    return x


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
