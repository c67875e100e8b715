"""Choosing the faults that explain an error: the objectives fault models are fitted against, forward
selection on BIC (the simplest explanation that clearly pays for itself), and the refit with residuals
whitened along the viewing rays."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from framechain.analysis.evidence.cross_camera import CrossCameraObjective
from framechain.analysis.evidence.static import RayObjective, StaticObjective
from framechain.analysis.fit.least_squares import NOISE_FLOOR_M, Fit, even_rows, fit_models, posterior_weights
from framechain.analysis.model.chain import ChainInputs, Perturbation, hop1, hop2, hop3
from framechain.analysis.model.fault import FaultModel, Mode
from framechain.analysis.model.faults import models_for, rotation_starts
from framechain.analysis.model.frame_swaps import swap_for_rotation
from framechain.arrays import FloatArray, IntArray
from framechain.catalogue import Fault, HopName
from framechain.geometry.transforms import transform_points
from framechain.progress import Progress
from framechain.timeline import PointRole

#: A fault must lower the BIC by this much to be reported (strong evidence on Kass-Raftery's scale).
MIN_BIC_GAIN = 10.0
#: A hop is divergent when its median departure exceeds this (m).
HOP_DIVERGENCE_M = 2e-3
MAX_FAULTS = 3
#: A joint refit on more than twice this many observations is first made on this many, evenly
#: spaced; when its mean squared residual there (above the BIC's noise floor) is this many times
#: that of the faults already found, it is not made on them all (it could not lower the BIC).
SCREEN_SUBSAMPLE = 2000
SCREEN_RATIO = 2.0


@dataclass(frozen=True)
class PointObjective:
    """Residual of one hop's output (or the world point) against logged or reference points."""

    stage: Literal["camera", "body", "world"]
    evidence: FloatArray
    hop_input: FloatArray | None = None  # the robot's own logged point of an earlier stage
    input_stage: Literal["camera", "body"] | None = None  # which stage ``hop_input`` is the output of
    weighting: RayWeighting | None = None

    def __call__(self, inputs: ChainInputs, pert: Perturbation) -> FloatArray:
        if self.stage == "camera":
            out = hop1(inputs, pert)
        else:
            p_cam = self.hop_input if self.input_stage == "camera" else None
            p_body = self.hop_input if self.input_stage == "body" else None
            if p_body is None:
                p_body = hop2(inputs, pert, p_cam if p_cam is not None else hop1(inputs, pert))
            if self.stage == "body":
                out = p_body
            else:
                out, ok = hop3(inputs, pert, p_body)
                out[~ok] = np.nan
        residual = out - self.evidence
        return residual if self.weighting is None else self.weighting.apply(residual)

    def take(self, index: IntArray) -> PointObjective:
        return replace(
            self, evidence=self.evidence[index], hop_input=None if self.hop_input is None else self.hop_input[index],
            weighting=None if self.weighting is None else self.weighting.take(index),
        )


@dataclass(frozen=True)
class RayWeighting:
    """Whitening of world residuals whose noise is larger along the viewing ray (depth noise).

    Depth noise moves a point along its ray, pixel noise across it; with the along-ray component
    scaled by ``weight = sigma_across / sigma_along`` the residuals are (close to) isotropic, which
    is what least squares assumes: a feasible generalised least-squares step.
    """

    rays_world: FloatArray  # (N, 3) unit viewing directions in the world frame
    weight: float

    def apply(self, residual: FloatArray) -> FloatArray:
        along = np.einsum("ij,ij->i", np.nan_to_num(residual), self.rays_world)
        out: FloatArray = residual + (self.weight - 1.0) * along[:, None] * self.rays_world
        return out

    def take(self, index: IntArray) -> RayWeighting:
        return replace(self, rays_world=self.rays_world[index])


Objective = PointObjective | StaticObjective | CrossCameraObjective


@dataclass(frozen=True)
class Selected:
    fit: Fit
    confidences: tuple[float, ...]
    alternatives: tuple[str, ...]  # next-best explanation at each step
    objective: Objective
    mode: Mode
    inputs: ChainInputs  # the observations the fit used (those with evidence)



def distances(residuals: FloatArray) -> FloatArray:
    out: FloatArray = np.linalg.norm(residuals, axis=1)
    return out



def hops_level(
    inputs: ChainInputs, matched: Mapping[PointRole, FloatArray], say: Progress
) -> tuple[list[Selected], dict[str, FloatArray], PointObjective, list[tuple[tuple[HopName, ...], PointObjective]]]:
    """Logged hops: each logged stage fed with the robot's own logged input, compared with its output.

    A stage whose input was not logged is fed from the raw inputs, and the faults of every hop
    upstream of it are candidates. Returns the selections, each logged hop's departure, the
    objective of the deepest logged stage (what the error is measured against), and each logged
    stage's objective with the hops whose faults it is examined for (what the bounds measure).
    """
    stages = (
        ("camera", HopName.PIXEL_TO_CAMERA, matched[PointRole.HOP_CAMERA]),
        ("body", HopName.CAMERA_TO_BODY, matched[PointRole.HOP_BODY]),
        ("world", HopName.BODY_TO_WORLD, matched[PointRole.HOP_WORLD]),
    )
    selections: list[Selected] = []
    hop_errors: dict[str, FloatArray] = {}
    previous: FloatArray | None = None  # the last logged stage's points: the next stage's input
    previous_stage: Literal["camera", "body"] | None = None
    upstream: list[HopName] = []
    deepest: PointObjective | None = None
    examined: list[tuple[tuple[HopName, ...], PointObjective]] = []
    for stage, hop, logged in stages:
        upstream.append(hop)
        if not np.isfinite(logged).all(axis=1).any():
            continue
        objective = PointObjective(stage, logged, previous, previous_stage)  # type: ignore[arg-type]
        departure = distances(objective(inputs, Perturbation()))
        hop_errors[hop.value] = departure
        examined.append((tuple(upstream), objective))
        if np.nanmedian(departure) > HOP_DIVERGENCE_M:
            say(f"classifying the departure at {hop.value}")
            sel = select(models_for(inputs, tuple(upstream)), objective, inputs, "as_run", say)
            if sel.fit.models:
                selections.append(sel)
        previous, previous_stage, upstream, deepest = logged, stage, [], objective  # type: ignore[assignment]
    assert deepest is not None  # the caller checked that some hop was logged
    # The deepest stage, fed from the raw inputs, is what the robot's chain did end to end.
    return selections, hop_errors, PointObjective(deepest.stage, deepest.evidence), examined


def select(
    models: Sequence[FaultModel],
    objective: Objective,
    inputs: ChainInputs,
    mode: Mode,
    say: Progress,
) -> Selected:
    """Forward selection on BIC: add the fault that explains most while it clearly pays for itself.

    Only observations with evidence take part (an unmatched point is no evidence, not an error).
    """
    rows = np.flatnonzero(np.isfinite(objective(inputs, Perturbation())).all(axis=1))
    if rows.size < len(inputs):
        objective, inputs = objective.take(rows), inputs.take(rows)
    current = fit_models([], objective, inputs)
    confidences: list[float] = []
    alternatives: list[str] = []
    while len(current.models) < MAX_FAULTS:
        used = {m.family for m in current.models}
        candidates = [m for m in models if m.family not in used]
        if not candidates:
            break
        quick = _alone_on_top(candidates, current, objective, inputs, mode, say)
        if not quick:
            break
        if current.models:  # refit the best few jointly with what was found before
            joint = _refit_jointly(quick[:3], current, objective, inputs)
            if not joint:
                break
            best_fit, best_model = joint[0]
        else:
            best_fit, best_model = quick[0][0], quick[0][1]
        if current.bic - best_fit.bic < MIN_BIC_GAIN:
            break
        say(f"found {best_model.name}")
        bics = [best_fit.bic, current.bic] + [f.bic for f, m in quick if m.name != best_model.name]
        confidences.append(float(posterior_weights(bics)[0]))
        runner_up = next((m.name for f, m in quick if m.name != best_model.name), "none")
        alternatives.append(runner_up)
        current = best_fit  # (alone, it is the quick fit on top of nothing: the same fit)
    return Selected(
        fit=current, confidences=tuple(confidences), alternatives=tuple(alternatives), objective=objective, mode=mode,
        inputs=inputs,
    )


def _alone_on_top(candidates: Sequence[FaultModel], current: Fit, objective: Objective, inputs: ChainInputs,
                  mode: Mode, say: Progress) -> list[tuple[Fit, FaultModel]]:
    """Each candidate fitted alone on top of the faults already found, best (lowest BIC) first; a fit that runs
    to the edge of its range explains by degenerating, not by a fault, and is left out."""
    base = current.perturbation()
    quick: list[tuple[Fit, FaultModel]] = []
    stage = f"fitting {len(candidates)} fault models" + (" on top of those found" if current.models else "")
    for k, candidate in enumerate(candidates):
        say(stage, k, len(candidates), "models")
        model = (
            replace(candidate, starts=rotation_starts(inputs, mode))
            if candidate.name.startswith("rotation")
            else candidate
        )
        quick.append((fit_models([model], objective, inputs, base=base), model))
    quick = [(fit, model) for fit, model in quick if not _explains_nothing(model, fit.params[-1])]
    quick.sort(key=lambda item: item[0].bic)
    return _prefer_edge_swaps(quick, inputs)


def _refit_jointly(best: Sequence[tuple[Fit, FaultModel]], current: Fit, objective: Objective, inputs: ChainInputs,
                   ) -> list[tuple[Fit, FaultModel]]:
    """The ``best`` candidates refitted jointly with the faults found (those hopeless jointly skipped), best
    first; a fit that runs to the edge of its range is left out."""
    x_prev = np.concatenate(current.params)
    joint = []
    for fit, model in best:
        x_start = np.concatenate([x_prev, fit.params[0]])
        if _hopeless_jointly(current, model, objective, inputs, x_start):
            continue
        joint.append((fit_models([*current.models, model], objective, inputs, x_start=x_start), model))
    joint = [(fit, model) for fit, model in joint if not _explains_nothing(model, fit.params[-1])]
    joint.sort(key=lambda item: item[0].bic)
    return joint


def _hopeless_jointly(current: Fit, model: FaultModel, objective: Objective, inputs: ChainInputs,
                      x_start: FloatArray) -> bool:
    """Whether ``model`` refitted jointly with the faults found cannot pay for itself: on an even
    subsample of a long log it explains the evidence far worse than they already do.

    A refit over every observation of a long log can take hundreds of evaluations of the chain
    (a discrete fault such as an inverted pose drags a latency along a rugged cost), and after a
    first fault most candidates are hopeless by orders of magnitude. A refit that passes is made
    over every observation from the same start, as before.
    """
    n = len(inputs)
    if n <= 2 * SCREEN_SUBSAMPLE:
        return False
    rows = even_rows(n, SCREEN_SUBSAMPLE)
    trial = fit_models([*current.models, model], objective.take(rows), inputs.take(rows), x_start=x_start)
    floor = NOISE_FLOOR_M**2
    found = float(np.sum(current.distances[rows] ** 2)) / trial.n_residuals
    return trial.rss / trial.n_residuals + floor >= SCREEN_RATIO * (found + floor)


def _prefer_edge_swaps(quick: list[tuple[Fit, FaultModel]], inputs: ChainInputs) -> list[tuple[Fit, FaultModel]]:
    """A fitted mount rotation that equals a path edge's rotation (within noise) is that edge skipped.

    When the best hypothesis is a free rotation and the frame swap whose rotation it matches fits
    about as well (within the BIC margin a finding must clear), the swap goes first: it names the
    frame to look up, where the rotation would name a 120 degree "calibration error".
    """
    if not quick or quick[0][1].fault != Fault.ROTATION_ERROR or quick[0][1].n_params == 0 or quick[0][1].camera:
        return quick
    frame = swap_for_rotation(inputs, quick[0][0].params[-1])
    if frame is None:
        return quick
    name = f"frame_swap[camera:{frame}]"
    swap = next((i for i, (_fit, model) in enumerate(quick) if model.name == name), None)
    if swap is None or quick[swap][0].bic - quick[0][0].bic > MIN_BIC_GAIN:
        return quick
    return [quick[swap], *(item for i, item in enumerate(quick) if i != swap)]


def _explains_nothing(model: FaultModel, x: FloatArray) -> bool:
    """A fit that ran to the edge of its range, or stayed within its evidence's tolerance."""
    return at_bound(model, x) or (model.tolerance is not None and model.tolerance(x))


def at_bound(model: FaultModel, x: FloatArray) -> bool:
    """Whether a fitted parameter sits on a bound of its plausible range (to 0.1 %)."""
    if not model.lower or not model.plausibility_bounds:
        return False
    lo, hi, x = np.asarray(model.lower, float), np.asarray(model.upper, float), np.asarray(x, float)
    near_lo = np.isfinite(lo) & (x <= lo + 1e-3 * np.abs(lo) + 1e-12)
    near_hi = np.isfinite(hi) & (x >= hi - 1e-3 * np.abs(hi) - 1e-12)
    return bool((near_lo | near_hi).any())


#: A fitted parameter within this share of its plausible range from an edge is at the edge of its search window
#: (a range over two decades, such as a scale's, measured in decades).
NEAR_EDGE = 0.05


def near_bound(model: FaultModel, x: FloatArray) -> bool:
    """Whether a fitted parameter lies near an edge of its plausible range (:data:`NEAR_EDGE` of it): its estimate
    is then the search window's as much as the evidence's."""
    if not model.lower or not model.plausibility_bounds:
        return False
    lo, hi, x = np.asarray(model.lower, float), np.asarray(model.upper, float), np.asarray(x, float)
    decades = (lo > 0) & (hi >= 100.0 * np.maximum(lo, 1e-300))
    position = np.where(decades, np.log(np.maximum(x, 1e-300) / np.maximum(lo, 1e-300))
                        / np.log(np.maximum(hi, 1e-300) / np.maximum(lo, 1e-300)), (x - lo) / (hi - lo))
    return bool(((position <= NEAR_EDGE) | (position >= 1.0 - NEAR_EDGE)).any())


def reweighted(sel: Selected) -> Selected:
    """Refit the chosen faults with residuals whitened along the viewing rays (noisy evidence only).

    The selection is kept; only the parameters (and their bootstrap) use the weighted residuals.
    """
    if not sel.fit.models or all(m.n_params == 0 for m in sel.fit.models):
        return sel
    if isinstance(sel.objective, RayObjective | CrossCameraObjective):  # across rays only, or between cameras
        return sel
    inputs = sel.inputs
    residual = sel.objective(inputs, sel.fit.perturbation())
    rays = transform_points(np.zeros_like(inputs.t_wb), inputs.q_wb,
                            transform_points(np.zeros_like(inputs.t_bc), inputs.q_bc, inputs.ray))
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    finite = np.isfinite(residual).all(axis=1)
    if finite.sum() < 10:
        return sel
    along = np.einsum("ij,ij->i", residual[finite], rays[finite])
    across = residual[finite] - along[:, None] * rays[finite]
    sigma_along = float(np.sqrt(np.mean(along**2)))
    sigma_across = float(np.sqrt(np.mean(np.sum(across**2, axis=1)) / 2.0))
    if sigma_along <= 0 or sigma_across <= 0:
        return sel
    weight = float(np.clip(sigma_across / sigma_along, 0.05, 1.0))
    objective = replace(sel.objective, weighting=RayWeighting(rays, weight))
    refit = fit_models(sel.fit.models, objective, inputs, x_start=np.concatenate(sel.fit.params), grid=False)
    return replace(sel, fit=refit, objective=objective)

