"""What each fault found is worth: its Shapley share of the median error (dropping the ones that move
noise), its bootstrap interval, and the sentence that says what it was found from."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from framechain.analysis.fit.least_squares import fit_models, perturbation_of
from framechain.analysis.fit.selection import Objective, Selected, at_bound, distances, near_bound
from framechain.analysis.fit.shapley import shapley_values
from framechain.analysis.model.chain import ChainInputs
from framechain.analysis.model.estimates import Estimate, estimate_scalars, format_estimate, format_interval
from framechain.analysis.model.fault import FaultModel, Mode
from framechain.analysis.model.faults import LATENCY_BOUND_S, TRANSLATION_BOUND_M
from framechain.analysis.verdict.checks import Bound, bound_family, size_text
from framechain.analysis.verdict.findings import Finding, Metric
from framechain.arrays import FloatArray
from framechain.catalogue import Fault
from framechain.progress import Progress

#: A fault found: its model, fitted parameters, confidence, the next-best explanation, and its selection.
Found = tuple[FaultModel, FloatArray, float, str, Selected]
#: A fault that explains less than this fraction of the median error, and less than the noise floor
#: of a median (two standard errors of the residual's median), is not a finding: its fit moved noise.
MIN_SHARE = 0.01
#: A finding whose confidence (the BIC weight of its explanation against the next best) is under this is
#: weak: another explanation is about as likely, and its fix is worded as a hint to check.
WEAK_CONFIDENCE = 0.5


def drop_unexplaining(
    found: list[Found],
    objective: Objective,
    inputs: ChainInputs,
    total: float,
) -> tuple[
    list[Found],
    list[float],
    list[Found],
]:
    """Drop, weakest first, the faults whose Shapley share of the median error is not a share of it.

    A share at or below zero means the fault makes the median error no better given the others. A
    Shapley value is a difference of medians, so one under two standard errors of the residual's
    median (1.2533 sigma / sqrt(n) for a median) cannot be told from noise; with it under
    :data:`MIN_SHARE` of the error as well (a true fault beside a large one can explain under 1% and
    still be far above the noise: a 30 ms latency beside a 30 deg mount) the fault is dropped.
    Shares are recomputed over the faults that remain after each drop (the parameters stay as
    fitted). Returns the kept faults, their Shapley values (m), and the dropped ones with the share
    they had when dropped.
    """
    kept = list(found)
    dropped: list[Found] = []
    while True:
        shapley = fault_shapley_values(kept, objective, inputs)
        if not kept:
            return kept, shapley, dropped
        combined = perturbation_of([f[0] for f in kept], np.concatenate([f[1] for f in kept]))
        residual = distances(objective(inputs, combined))
        residual = residual[np.isfinite(residual)]
        floor = 2.0 * 1.2533 * float(np.std(residual)) / math.sqrt(residual.size) if residual.size else 0.0
        weakest = int(np.argmin(shapley))
        value = shapley[weakest]
        if value > 0 and not (value < MIN_SHARE * total and value < floor):
            return kept, shapley, dropped
        model, x, _confidence, _alternative, sel = kept.pop(weakest)
        why = ("it does not lower the median error given the other faults" if value <= 0 else
               f"under {MIN_SHARE:.0%} of it and under the noise floor of a median ({floor * 1e3:.2f} mm, two "
               "standard errors)")
        dropped.append((model, x, value, why, sel))


def fault_shapley_values(
    found: Sequence[Found], objective: Objective, inputs: ChainInputs
) -> list[float]:
    """Shapley values of the median error explained, over the faults found (2^k replays)."""

    def lowered(subset: frozenset[int]) -> float:
        """Minus the median error with the faults ``subset`` applied: the error each coalition takes away."""
        chosen = [found[i] for i in sorted(subset)]
        pert = perturbation_of(
            [c[0] for c in chosen], np.concatenate([c[1] for c in chosen]) if chosen else np.zeros(0)
        )
        return -float(np.nanmedian(distances(objective(inputs, pert))))

    return shapley_values(len(found), lowered)


@dataclass(frozen=True)
class Bootstrapped:
    """A bootstrap of one model: the 95% intervals of its scalar estimates, and the share of resamples whose refit
    ran to the edge of the model's search window (its estimate is then the window's, not the evidence's)."""

    interval: dict[str, list[float]]
    at_edge: float = 0.0


def own_effect(found: Sequence[Found], k: int, objective: Objective, inputs: ChainInputs) -> float | None:
    """A rig camera's finding ``found[k]``: the median error of that camera's own observations without it (the
    other findings kept) less with every finding (m); None for a finding of the chain as a whole."""
    model = found[k][0]
    if model.camera is None or inputs.camera_index is None:
        return None
    camera = next(i for i, c in enumerate(inputs.rig_cameras) if c.frame == model.camera)
    rows = inputs.camera_index == camera

    def error(chosen: Sequence[Found]) -> FloatArray:
        params = np.concatenate([c[1] for c in chosen]) if chosen else np.zeros(0)
        pert = perturbation_of([c[0] for c in chosen], params)
        out: FloatArray = distances(objective(inputs, pert))[rows]
        return out

    with_all, without = error(found), error([f for i, f in enumerate(found) if i != k])
    both = np.isfinite(with_all) & np.isfinite(without)
    return float(np.median(without[both]) - np.median(with_all[both])) if both.any() else None


def refit_bootstrap(sel: Selected, model: FaultModel, rng: np.random.Generator, draws: int, say: Progress
                    ) -> Bootstrapped:
    """The model refitted on ``draws`` observation resamples (drawn with replacement): its 95% intervals and how
    often it ran to its edge. (A camera's motion is bootstrapped otherwise: blocks of frame pairs reweighted on
    a grid, nothing refitted, :func:`framechain.analysis.egomotion.solve.block_bootstrap`.)"""
    if model.n_params == 0:
        return Bootstrapped({})
    stage = f"bootstrapping {model.name}"
    say(stage, 0, draws, "resamples")
    x_fit = np.concatenate(sel.fit.params)
    index = [m.name for m in sel.fit.models].index(model.name)
    samples: dict[str, list[float]] = {}
    inputs = sel.inputs
    n = len(inputs)
    edges = 0
    for draw in range(draws):
        idx = rng.integers(0, n, n)
        refit = fit_models(sel.fit.models, sel.objective.take(idx), inputs.take(idx), x_start=x_fit, grid=False)
        edges += at_bound(model, refit.params[index])
        scalars = estimate_scalars(model.estimate(refit.params[index], sel.mode, inputs))
        for key, value in scalars.items():
            samples.setdefault(key, []).append(float(value))
        say(stage, draw + 1, draws, "resamples")
    return Bootstrapped({k: [round(float(np.percentile(v, 2.5)), 6), round(float(np.percentile(v, 97.5)), 6)]
                         for k, v in samples.items()}, edges / max(draws, 1))


#: A factor or scale whose 95% interval spans more than this ratio spans orders of magnitude: undetermined.
UNDETERMINED_RATIO = 10.0
#: A rotation whose 95% interval is wider than this (deg) cannot say how the mount is turned: undetermined.
UNDETERMINED_ANGLE_DEG = 45.0
#: An interval reaching this share of a search window's half-width reaches its edge.
WINDOW_EDGE = 0.9
#: A fit with at least this share of its bootstrap refits at the edge of its search window is at the edge.
UNDETERMINED_EDGE_SHARE = 0.25


def undetermined_because(model: FaultModel, x: FloatArray, interval: dict[str, list[float]], at_edge: float
                         ) -> tuple[str, ...]:
    """Why a fit's estimate (``x``) cannot be trusted (empty: it can): it lies at the edge of its search window, its
    95% interval spans orders of magnitude, is wider than a rotation can be read from, or reaches that edge; or its
    bootstrap refits run to the edge."""
    why = []
    if near_bound(model, x):
        why.append("it lies at the edge of its search window")
    for key, (lo, hi) in interval.items():
        text = format_interval({key: [lo, hi]})
        if key in ("factor", "scale") and lo > 0 and hi / lo > UNDETERMINED_RATIO:
            why.append(f"its 95% interval {text} spans {math.log10(hi / lo):.1f} orders of magnitude")
        elif key == "offset_s" and max(abs(lo), abs(hi)) >= WINDOW_EDGE * LATENCY_BOUND_S:
            why.append(f"its 95% interval {text} reaches the edge of the +-{LATENCY_BOUND_S:g} s searched")
        elif key == "angle_deg" and hi - lo > UNDETERMINED_ANGLE_DEG:
            why.append(f"its 95% interval {text} is {hi - lo:.0f} deg wide")
        elif key == "distance_m" and hi >= WINDOW_EDGE * TRANSLATION_BOUND_M:
            why.append(f"its 95% interval {text} reaches the edge of the {TRANSLATION_BOUND_M * 1e3:g} mm searched")
    if at_edge >= UNDETERMINED_EDGE_SHARE:
        why.append(f"{at_edge:.0%} of its bootstrap refits ran to the edge of its search window")
    return tuple(why)


def evidence_sentence(
    fault: Fault, model: FaultModel, metric: Metric, estimate: Estimate, alternative: str, mode: Mode,
    *, spread_m: tuple[float, float] = (math.nan, math.nan), rays: bool = False,
) -> str:
    """``spread_m``: the static objects' median spread before, and after this fault's share of it."""
    before, after = spread_m
    measured = ("how far each static object's rays pass from their meeting point" if rays
                else "the spread of each static object's world points")
    where = {
        "logged_hops": f"the robot's logged {model.hop.value.split('_to_')[-1]} points depart from the recomputed hop",
        "target": "the logged target is reproduced from the raw inputs",
        "reference": "the error against the reference vanishes",
        "static_spread": f"{measured} (median {before * 1e3:.3g} mm) shrinks to {after * 1e3:.3g} mm",
        "cross_camera": (f"the disagreement between the rig's cameras (median {before * 1e3:.3g} mm) shrinks to "
                         f"{after * 1e3:.3g} mm"),
    }[metric]
    side = "recorded data" if mode == "correction" else "chain that produced the evidence"
    return (
        f"With {fault.value} ({format_estimate(estimate)}) in the {side}, {where}; "
        f"next-best explanation: {alternative}."
    )



#: What to check before acting on a weak finding, per fault.
_CHECK = {
    Fault.LATENCY: "the header stamps of the detections against those of the poses (`framechain info` shows "
                   "each topic's stamp delay)",
    Fault.ROTATION_ERROR: "the mount against a fresh extrinsic calibration",
    Fault.MISSING_ROTATION: "the mount against a fresh extrinsic calibration",
    Fault.TRANSLATION_ERROR: "the mount's position against a measured one (or a fresh extrinsic calibration)",
    Fault.DEPTH_SCALE: "the declared tag size or the depth units against a measured distance",
    Fault.INTRINSICS: "the calibration against the camera's own (a fresh calibration or the driver's CameraInfo)",
}


def weakened(findings: Sequence[Finding], bounds: Sequence[Bound]) -> tuple[Finding, ...]:
    """The findings, those that are weak marked and their fix worded as a hint.

    Weak: a 95% interval that holds "no fault" (an offset of 0, a factor or scale of 1), a
    confidence under :data:`WEAK_CONFIDENCE`, or an estimate smaller than the bound of its family
    (the smallest fault of it this log shows reliably: a finding under it cleared the thresholds by
    the luck of the noise).
    """
    out = []
    for finding in findings:
        why = _weak_because(finding, bounds)
        if not why:
            out.append(finding)
            continue
        check = _CHECK.get(finding.fault, "the frame names and directions of the chain against the robot's URDF "
                           "or /tf")
        fix = (f"weak ({'; '.join(why)}): check {check} before changing anything; if it holds up: "
               f"{finding.fix[:1].lower()}{finding.fix[1:]}")
        out.append(replace(finding, fix=fix, strength="weak", weak_because=why))
    return tuple(out)


def _weak_because(finding: Finding, bounds: Sequence[Bound]) -> tuple[str, ...]:
    why = []
    scalars = estimate_scalars(finding.estimate)
    for key, (lo, hi) in finding.interval.items():
        none = 0.0 if key == "offset_s" else 1.0 if key in ("factor", "scale") else None
        if none is not None and lo <= none <= hi:
            why.append(f"its 95% interval {format_interval({key: [lo, hi]})} holds no fault")
    if finding.confidence < WEAK_CONFIDENCE:
        why.append(f"confidence {finding.confidence:.2f} under {WEAK_CONFIDENCE:g}")
    family = bound_family(finding.fault)
    bound = next((b for b in bounds if b.fault == family and b.hop == finding.hop and b.camera == (finding.camera or "")
                  and b.statistical_size is not None), None)
    if bound is not None and bound.statistical_size is not None and scalars:
        value = next(iter(scalars.values()))
        directed = (Fault.LATENCY, Fault.ROTATION_ERROR, Fault.TRANSLATION_ERROR)
        size = abs(value) if family in directed else abs(value - 1.0)
        if size < bound.statistical_size:
            why.append(f"under the {size_text(family, bound.statistical_size)} this log shows reliably")
    return tuple(why)
