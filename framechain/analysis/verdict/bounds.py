"""Bounds: whether this log's evidence can see each fault family, and the smallest fault of it that
framechain's own thresholds would have made a finding.

For every family with a size (a time offset, the mount rotation, a depth or intrinsics scale) at each
hop a stage of the evidence can fit it at, measured with the fit's own objective (which profiles
out its nuisance parameters, such as each static target's position):

1. **The signal of a fault.** The objective is evaluated on noise-free copies of the observations
   (each static target's sightings rewritten to land exactly on its fitted position: an objective
   that re-fits positions would otherwise see its own noise rotate or scale and call that a
   signal), with the findings applied and the family's parameter moved by ``a``: the residuals it
   adds are the fault's signal ``S(a)``. A logged point, a target or a reference has no nuisance:
   there ``S(a)`` is the change of the chain's output.
2. **framechain's thresholds.** ``a`` is detectable when the signal clears forward selection's BIC
   gain (:data:`~framechain.analysis.fit.selection.MIN_BIC_GAIN` plus ``k log n`` plus the model's
   choice penalty, against the residual variance left by the findings with the noise floor),
   survives the Shapley drop rule (its share of the median error is above 1 % of it or above the
   noise floor of a median, by the share's own standard error: it is a noisy statistic) and, with
   logged hops, lifts the hop's median departure past
   :data:`~framechain.analysis.fit.selection.HOP_DIVERGENCE_M`.
3. **The smallest such size**, searched from the linearised one (the Jacobian of the objective by
   central differences) outwards, then bisected, in either direction (the worse is kept), and
   detected at every larger size checked (up to four times it); a
   rotation is searched along its weakest axis (the eigenvector of ``J^T J`` with the smallest
   eigenvalue), and axes whose Jacobian vanishes are named as not observable. A family whose
   signal stays under the thresholds over the whole range searched (a second of time offset,
   90 deg, a factor of 0.2..1.8) is not observable.
4. **Checked by injection.** A fault of that size is written into this log's own data (the pixels
   and depths a static target's objective sees, or the logged points, target or reference) and refitted from no
   fault, either way round; when neither refit clears the thresholds the bound is raised by half and
   checked again (twice at most).

A rig (:mod:`~framechain.analysis.evidence.cross_camera`) is bounded per camera with that camera's own models
(:attr:`Stage.models`): its noise-free observations are where the cameras meet
(:meth:`~framechain.analysis.evidence.cross_camera.CrossCameraObjective.consensus`), a fault is written into one
camera's pixels and depths, or into its stamps when the rig's pose does not change with time, and a fault
within its model's tolerance is never a finding (so never under the bound).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from framechain.analysis.evidence.cross_camera import CrossCameraObjective
from framechain.analysis.fit.least_squares import NOISE_FLOOR_M, fit_models, perturbation_of
from framechain.analysis.fit.selection import MIN_BIC_GAIN, Objective, PointObjective, at_bound
from framechain.analysis.fit.shares import MIN_SHARE
from framechain.analysis.model.chain import CameraDelta, ChainInputs, Perturbation, hop1
from framechain.analysis.model.estimates import axis_text
from framechain.analysis.model.fault import FaultModel, Mode
from framechain.analysis.model.faults import models_for
from framechain.analysis.verdict.bound_signal import (
    MAX_SIZE,
    SIZED,
    Found,
    Noise,
    Probe,
    Stage,
    clean_observations,
    fault_params,
    median_norm,
    observations_for,
    why_blind,
    world_of,
)
from framechain.analysis.verdict.checks import DIRECTED, SIZE_KEYS, Bound, family_name, size_text, tolerance_text
from framechain.arrays import FloatArray
from framechain.catalogue import Fault, HopName

#: Bisection steps between the last undetected and the first detected size (each halves a factor of 1.5).
BISECT = 6
#: A bound must also be detected at these multiples of it (up to 4x: twice the test's 2x), and the
#: search restarts past a failure at most this many times.
STABLE_FACTORS = (1.25, 1.5, 2.0, 3.0, 4.0)
STABLE_RESTARTS = 6
#: Times the injection check raises a bound (by half) when the refit does not find the fault.
INJECTION_RETRIES = 2


def bounds(stages: Sequence[Stage], found: Found, *, say: Callable[[str], None] = lambda _m: None,
           no_depth: bool = False, tolerance_m: float = 0.0) -> tuple[Bound, ...]:
    """One :class:`Bound` per sized fault family and hop the stages can fit (``found``: the findings'
    models and parameters). ``no_depth``: bearing-only evidence, where a depth scale has nothing to scale;
    ``tolerance_m``: the effect worth acting on, under which a fault is no finding (0: the noise alone)."""
    out: list[Bound] = []
    for stage in stages:
        mine = [(m, x) for m, x in found if m.hop in stage.hops]
        base = perturbation_of([m for m, _ in mine], np.concatenate([x for _, x in mine]) if mine else np.zeros(0))
        candidates = bounds_candidates(stage, mine)
        if not candidates:
            continue
        say(f"bounding what the evidence can see at {', '.join(h.value for h in stage.hops)}")
        noise = Noise.of(stage, base)
        clean = clean_observations(stage, base)
        for fault, hop, variants in candidates:
            others = [(m, x) for m, x in mine if m.n_params and m.family != variants[0][0].family]
            results = [_bound_one(Probe(stage, *clean, base, model, theta0, others), noise, tolerance_m)
                       for model, theta0 in variants]
            out.append(_assemble(stage, fault, hop, results, noise, tolerance_m))
    if no_depth:
        out.append(Bound(HopName.PIXEL_TO_CAMERA, Fault.DEPTH_SCALE, False, None,
                         "bearing only: the detections carry no depth to scale"))
    return tuple(sorted(out, key=lambda b: (*family_order(b.fault, b.hop), b.camera or "")))


def family_order(fault: Fault, hop: HopName) -> tuple[int, int]:
    """Latency first (pose, then camera), then the mount rotation, the depth scale, the intrinsics."""
    return SIZED.index(fault), -list(HopName).index(hop)


def without_evidence(inputs: ChainInputs) -> tuple[Bound, ...]:
    """Every sized family not observable: there is nothing to measure the chain against."""
    families = [(Fault.LATENCY, HopName.BODY_TO_WORLD)]
    if inputs.camera_is_dynamic:
        families.append((Fault.LATENCY, HopName.CAMERA_TO_BODY))
    families += [(Fault.ROTATION_ERROR, HopName.CAMERA_TO_BODY), (Fault.TRANSLATION_ERROR, HopName.CAMERA_TO_BODY),
                 (Fault.DEPTH_SCALE, HopName.PIXEL_TO_CAMERA), (Fault.INTRINSICS, HopName.PIXEL_TO_CAMERA)]
    return tuple(Bound(hop, fault, False, None, "no evidence to measure the chain against") for fault, hop in families)


def bounds_candidates(stage: Stage, mine: Found) -> list[tuple[Fault, HopName, list[tuple[FaultModel, FloatArray]]]]:
    """The sized families at the stage's hops, each with its models (two intrinsics variants) and the
    parameters they start from (a finding's own, else no fault)."""
    by_family: dict[tuple[Fault, HopName, str | None], list[tuple[FaultModel, FloatArray]]] = {}
    found_by_family = {m.family: (m, x) for m, x in mine}
    models = stage.models if stage.models is not None else models_for(stage.inputs, stage.hops, blind=stage.static)
    for model in models:
        if model.fault not in SIZED or model.n_params == 0 or (stage.rays and model.fault == Fault.DEPTH_SCALE):
            continue
        theta0 = np.asarray(model.x0, dtype=float)
        if model.family in found_by_family:
            other, x = found_by_family[model.family]
            if other.n_params and other.name != model.name:
                continue  # another variant was found (intrinsics): its own model bounds the family
            if other.name == model.name:
                theta0 = np.asarray(x, dtype=float)
        by_family.setdefault((model.fault, model.hop, model.camera), []).append((model, theta0))
    return [(fault, hop, variants) for (fault, hop, _camera), variants in by_family.items()]


@dataclass(frozen=True)
class _Result:
    model: FaultModel
    size: float | None  # parameter units (s, rad, deviation); None: not observable
    direction: FloatArray
    unobservable: tuple[FloatArray, ...] = ()  # rotation axes the evidence cannot see
    best: float | None = None  # the rotation's best-seen axis size (rad)
    refound: float | None = None  # what the injection check's refit gave (the estimate's key)
    injected: float | None = None
    confirmed: bool = True  # the injection check's refit cleared the thresholds
    tolerated: bool = False  # the model's tolerance, not the evidence, sets the size (a smaller fault is no finding)
    statistical: float | None = None  # the size the noise alone sets (parameter units), when the tolerance sets size


def _bound_one(probe: Probe, noise: Noise, tolerance_m: float = 0.0) -> _Result:
    """The smallest fault of the probe's model the noise lets the fit find, raised to the smallest that moves the
    median error by ``tolerance_m`` where that is larger (``statistical`` keeps the first)."""
    model = probe.model
    jac = probe.jacobian()
    values, vectors = np.linalg.eigh(jac.T @ jac)
    needed = noise.needed_ss(model)
    limit = MAX_SIZE[model.fault]
    linear = np.sqrt(needed / np.maximum(values, 1e-300))
    blind: list[FloatArray] = []
    for k in range(len(values)):  # eigh sorts ascending: the weakest axis first
        direction = vectors[:, k]
        size = None
        if linear[k] <= limit or _detected_at(probe, noise, direction, limit):
            size = _smallest(probe, noise, direction, float(min(linear[k], limit)), limit)
        if size is None:
            blind.append(direction)
            continue
        best = float(min(linear[-1], limit)) if len(values) > 1 else None
        practical = _practical(probe, noise, direction, size, limit, tolerance_m)
        if practical <= size:
            return _checked(noise, probe, direction, size, tuple(blind), best)
        return replace(_checked(noise, probe, direction, practical, tuple(blind), best), statistical=size)
    return _Result(model, None, vectors[:, 0], tuple(blind))


def _practical(probe: Probe, noise: Noise, direction: FloatArray, size: float, limit: float,
               tolerance_m: float) -> float:
    """The smallest fault from ``size`` up that also moves the median error by ``tolerance_m`` (``limit`` when none
    up to it does; ``size`` itself when it already does, or without a tolerance)."""
    if tolerance_m <= 0:
        return size
    gated = replace(noise, tolerance_m=tolerance_m)
    if _detected_at(probe, gated, direction, size) and all(
            _detected_at(probe, gated, direction, f * size) for f in STABLE_FACTORS[:2] if f * size <= limit):
        return size
    found = _smallest(probe, gated, direction, size, limit)
    return limit if found is None else max(found, size)


def _detected_at(probe: Probe, noise: Noise, direction: FloatArray, a: float) -> bool:
    """Detected at size ``a`` in both directions (the worse counts)."""
    thetas = [fault_params(probe.model, probe.theta0, s * direction, a) for s in (1.0, -1.0)]
    return all(noise.detected(probe.signal(theta), probe.model, theta) for theta in thetas)


def _smallest(probe: Probe, noise: Noise, direction: FloatArray, start: float, limit: float) -> float | None:
    """The smallest size detected in both directions and at every larger size checked (the median share
    of a small fault jumps with the noise: a size detected once may not be at 1.5 times it), from
    ``start`` down (or up) by factors of 1.5 to a crossing, then bisected; None when nothing up to
    ``limit`` is detected."""
    a = max(start, 1e-9)
    for _ in range(STABLE_RESTARTS):
        crossing = _crossing(probe, noise, direction, a, limit)
        if crossing is None:
            return None
        failing = next((f * crossing for f in STABLE_FACTORS if f * crossing <= limit
                        and not _detected_at(probe, noise, direction, f * crossing)), None)
        if failing is None:
            return crossing
        a = failing * 1.5  # undetected above the crossing: search on from past where it failed
        if a > limit:
            return None
    return None


def _crossing(probe: Probe, noise: Noise, direction: FloatArray, a: float, limit: float) -> float | None:
    """A size where detection starts (the first detected going up, or the last going down from ``a``)."""
    if _detected_at(probe, noise, direction, a):
        low, high = a / 1.5, a
        while low > 1e-9 and _detected_at(probe, noise, direction, low):
            low, high = low / 1.5, low
    else:
        low, high = a, a * 1.5
        while not _detected_at(probe, noise, direction, min(high, limit)):
            if high >= limit:
                return None
            low, high = high, high * 1.5
        high = min(high, limit)
    for _ in range(BISECT):
        mid = float(np.sqrt(low * high))
        low, high = (low, mid) if _detected_at(probe, noise, direction, mid) else (mid, high)
    return high


# -- the check by injection -------------------------------------------------------------------
def _injected(stage: Stage, base: Perturbation, model: FaultModel, theta0: FloatArray,
              theta: FloatArray) -> tuple[Objective, ChainInputs]:
    """This log's observations with the fault ``theta`` written in (fitting it recovers ``theta``)."""
    objective, inputs = stage.objective, stage.inputs
    if isinstance(objective, PointObjective):
        change = objective(inputs, model.apply(base, theta)) - objective(inputs, model.apply(base, theta0))
        return replace(objective, evidence=objective.evidence + np.nan_to_num(change)), inputs
    if isinstance(objective, CrossCameraObjective):
        return _injected_rig(objective, model.apply(base, theta0), model.apply(base, theta)), inputs
    world = world_of(inputs, model.apply(base, theta0), hop1(inputs, model.apply(base, theta0)))
    return objective, observations_for(inputs, model.apply(base, theta), world, keep_depth=stage.rays)


def _injected_rig(objective: CrossCameraObjective, start: Perturbation, faulty: Perturbation) -> CrossCameraObjective:
    """A rig's observations with a fault written in: a camera's stamps moved (a rig whose pose does not change
    with time shows a stamp offset only in which sightings meet), else its pixels and depths rewritten."""
    shifts = {k: -round((d.offset_s - start.cameras.get(k, CameraDelta()).offset_s) * 1e9)
              for k, d in faulty.cameras.items()}
    shifts = {k: ns for k, ns in shifts.items() if ns}
    if shifts and objective.timeless_pose:
        return objective.restamped(shifts)
    rig = objective.rig
    world = world_of(rig, start, hop1(rig, start))
    return objective.over(observations_for(rig, faulty, world))


def refound(stage: Stage, noise: Noise, base: Perturbation, model: FaultModel, theta0: FloatArray,
            theta: FloatArray, others: Found = ()) -> tuple[bool, FloatArray]:
    """Inject ``theta``, refit the model from no fault (with the other findings' parameters refitted
    beside it, as selection does): whether the refit clears the thresholds, and its fit."""
    objective, inputs = _injected(stage, base, model, theta0, theta)
    models = [m for m, _ in others]
    x_others = np.concatenate([x for _, x in others]) if others else np.zeros(0)
    without = fit_models(models, objective, inputs, base=base, x_start=x_others, grid=False)
    fitted = fit_models([*models, model], objective, inputs, base=base, x_start=np.concatenate([x_others, theta0]),
                        grid=False)
    before, after = float(np.median(without.distances)), float(np.median(fitted.distances))
    floor = 2.0 * 1.2533 * float(np.std(fitted.distances)) / np.sqrt(max(fitted.distances.size, 1))
    share = before - after
    ok = (without.bic - fitted.bic >= MIN_BIC_GAIN and share > 0 and not (share < MIN_SHARE * before and share < floor)
          and not at_bound(model, fitted.params[-1])  # a fit on its plausible range's edge is no finding
          and not (model.tolerance is not None and model.tolerance(fitted.params[-1])))
    if ok and noise.gate_m is not None and median_norm(noise.departure) <= noise.gate_m:
        ok = median_norm(objective(inputs, Perturbation())) > noise.gate_m
    return ok, fitted.params[-1]


def _checked(noise: Noise, probe: Probe, direction: FloatArray, size: float, blind: tuple[FloatArray, ...],
             best: float | None) -> _Result:
    """Inject the fault at ``size`` (either way) and refit; raise the size by half while neither is found.

    At the bound itself the refit clears the thresholds about half the time (the bound is where the
    expected gain meets them): both directions are tried before the bound is called optimistic.
    """
    stage, model, theta0 = probe.stage, probe.model, probe.theta0
    first = _worse_sign(probe, direction, size)
    theta, fitted, ok = theta0, theta0, False
    for attempt in range(INJECTION_RETRIES + 1):
        for sign in (first, -first):
            theta = fault_params(model, theta0, sign * direction, size)
            ok, fitted = refound(stage, noise, probe.base, model, theta0, theta, probe.others)
            if ok:
                break
        if ok or attempt == INJECTION_RETRIES or size * 1.5 > MAX_SIZE[model.fault]:
            break
        size *= 1.5
    below = fault_params(model, theta0, direction, 0.98 * size)
    tolerated = model.tolerance is not None and model.tolerance(below)
    return _Result(model, size, direction, blind, best, _size_of(model, theta0, fitted, stage.mode),
                   _size_of(model, theta0, theta, stage.mode), ok, tolerated)


def _worse_sign(probe: Probe, direction: FloatArray, size: float) -> float:
    """The direction whose fault of ``size`` adds the smaller signal."""
    energy = [float(np.sum(probe.signal(fault_params(probe.model, probe.theta0, s * direction, size)) ** 2))
              for s in (1.0, -1.0)]
    return 1.0 if energy[0] <= energy[1] else -1.0


def _size_of(model: FaultModel, theta0: FloatArray, theta: FloatArray, mode: Mode) -> float:
    """How far ``theta`` is from ``theta0`` in the estimate's key (ms as s, deg, a scale's deviation)."""
    if model.fault == Fault.LATENCY:
        return float(theta[0] - theta0[0])
    if model.fault == Fault.ROTATION_ERROR:
        return float(np.rad2deg(np.linalg.norm(theta - theta0)))
    if model.fault == Fault.TRANSLATION_ERROR:
        return float(np.linalg.norm(theta - theta0))
    ratio = float(theta[0] / theta0[0])
    return (ratio if mode == "as_run" else 1.0 / ratio) - 1.0


# -- the bound in words -----------------------------------------------------------------------
def _assemble(stage: Stage, fault: Fault, hop: HopName, results: Sequence[_Result], noise: Noise,
              tolerance_m: float = 0.0) -> Bound:
    """The family's bound: the worse of its models (intrinsics: two variants), with the sentence."""
    camera = results[0].model.camera or ""  # a rig camera's own models name it
    blind = [r for r in results if r.size is None]
    if blind:
        return Bound(hop, fault, False, None, why_blind(stage, fault, hop), camera=camera)
    worst = max(results, key=lambda r: r.size or 0.0)
    assert worst.size is not None
    size = _estimate_size(fault, worst.size, stage.mode)
    statistical = None if worst.statistical is None else _estimate_size(fault, worst.statistical, stage.mode)
    axes = tuple(_axis3(v) for v in worst.unobservable)
    n_obs = len(stage.inputs)
    over = f"{n_obs} observations"
    if worst.model.camera is not None and stage.inputs.camera_index is not None:
        k = next(i for i, c in enumerate(stage.inputs.rig_cameras) if c.frame == worst.model.camera)
        mine = int((stage.inputs.camera_index == k).sum())
        over = f"{n_obs} observations ({mine} of {worst.model.camera}, measured against the other cameras)"
    name = "latency (stamp offset)" if fault == Fault.LATENCY and worst.model.camera else family_name(fault, hop)
    what = f"{size_text(fault, size)} is the smallest {name}{_direction_text(fault, worst)}"
    if len(results) > 1:
        what += f" (of K's variants, {worst.model.name} is the harder to see)"
    axis = _axis3(worst.direction) if fault in DIRECTED else None
    key = SIZE_KEYS[fault]
    return Bound(hop, fault, True, {key: round(size, 6)},
                 f"{what} that clears the BIC gain ({MIN_BIC_GAIN:g} + k log n) and the share rule against "
                 f"{_noise_text(noise)} over {over}{_limit_text(fault, statistical, tolerance_m)}"
                 f"{_check_text(stage, fault, worst)}.", axes, axis, camera,
                 statistical=None if statistical is None else {key: round(statistical, 6)},
                 limited_by="tolerance" if statistical is not None else "cross-check" if worst.tolerated else "noise",
                 tolerance_m=tolerance_m)


def _direction_text(fault: Fault, worst: _Result) -> str:
    """`` (about [..], the weakest axis seen; 0.1 deg about the best)`` for a rotation, ``along`` for a translation."""
    if fault not in DIRECTED:
        return ""
    about, what = ("along", "direction") if fault == Fault.TRANSLATION_ERROR else ("about", "axis")
    text = f" ({about} {axis_text(_unit(worst.direction).tolist())}, the weakest {what} seen"
    if worst.best is None:
        return text + ")"
    best = f"{np.rad2deg(worst.best):.2g} deg" if fault == Fault.ROTATION_ERROR else f"{worst.best * 1e3:.2g} mm"
    return text + f"; {best} {about} the best)"


def _noise_text(noise: Noise) -> str:
    rms_mm = float(np.sqrt(max(noise.variance - NOISE_FLOOR_M**2, 0.0) * 3.0)) * 1e3
    text = f"{rms_mm:.2g} mm rms of residual"
    if rms_mm < np.sqrt(3.0) * NOISE_FLOOR_M * 1e3:  # the BIC's noise floor sets the scale, not the residual
        text += f" (under the BIC's {NOISE_FLOOR_M * 1e3:g} mm noise floor per axis, which counts instead)"
    return text


def _limit_text(fault: Fault, statistical: float | None, tolerance_m: float) -> str:
    if statistical is None:
        return ""
    return (f", and moves the median error by the {tolerance_text(tolerance_m)} tolerance (tolerance_m): from "
            f"{size_text(fault, statistical)} the noise would let it be found, but it would change the error by "
            "less, a note")


def _check_text(stage: Stage, fault: Fault, worst: _Result) -> str:
    check = ""
    if worst.refound is not None and worst.injected is not None:
        where = "observations" if stage.static else "logged points"
        check = (f"; written into this log's {where} at {_key_text(fault, worst.injected)} and refitted from no "
                 f"fault: {_key_text(fault, worst.refound)}")
        if not worst.confirmed:
            check += " (not a finding even there: this bound is optimistic)"
    if worst.tolerated:
        check += ("; the tolerance of a rig camera's fault sets it (a smaller one is no finding however well it "
                  "fits), not the evidence")
    return check


def _estimate_size(fault: Fault, size: float, mode: Mode) -> float:
    """A parameter size (s, rad, a scale's deviation ``a``) in the estimate's key: degrees; a corrected
    scale ``1 +- a`` is the fault ``1 / (1 +- a)``, whose larger deviation from 1 is ``a / (1 - a)``."""
    if fault == Fault.ROTATION_ERROR:
        return float(np.rad2deg(size))
    if fault == Fault.TRANSLATION_ERROR:
        return size
    if fault in (Fault.DEPTH_SCALE, Fault.INTRINSICS) and mode == "correction":
        return size / (1.0 - size)
    return size


def _key_text(fault: Fault, value: float) -> str:
    if fault == Fault.LATENCY:
        return f"{value * 1e3:+.2f} ms"
    if fault == Fault.ROTATION_ERROR:
        return f"{value:.3g} deg"
    if fault == Fault.TRANSLATION_ERROR:
        return f"{value * 1e3:.3g} mm"
    return f"{value * 100:+.3g}%"


def _axis3(v: FloatArray) -> tuple[float, float, float]:
    """A unit axis, rounded (``+ 0.0`` drops negative zeros)."""
    x, y, z = (round(float(c), 4) + 0.0 for c in _unit(v))
    return x, y, z


def _unit(v: FloatArray) -> FloatArray:
    out: FloatArray = v / max(float(np.linalg.norm(v)), 1e-300)
    return out


__all__ = ["SIZED", "Stage", "bounds", "bounds_candidates", "family_order", "observations_for", "refound",
           "without_evidence"]
