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
   gain (:data:`~framechain.analysis.selection.MIN_BIC_GAIN` plus ``k log n`` plus the model's
   choice penalty, against the residual variance left by the findings with the noise floor),
   survives the Shapley drop rule (its share of the median error is above 1 % of it or above the
   noise floor of a median, by the share's own standard error: it is a noisy statistic) and, with
   logged hops, lifts the hop's median departure past
   :data:`~framechain.analysis.selection.HOP_DIVERGENCE_M`.
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

A rig (:mod:`~framechain.analysis.cross_camera`) is bounded per camera with that camera's own models
(:attr:`Stage.models`): its noise-free observations are where the cameras meet
(:meth:`~framechain.analysis.cross_camera.CrossCameraObjective.consensus`), a fault is written into one
camera's pixels and depths, or into its stamps when the rig's pose does not change with time, and a fault
within its model's tolerance is never a finding (so never under the bound).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from framechain.analysis.chain_model import CameraDelta, ChainInputs, Perturbation, hop1, hop2, hop3
from framechain.analysis.checks import DIRECTED, SIZE_KEYS, Bound, family_name, size_text, tolerance_text
from framechain.analysis.cross_camera import CrossCameraObjective
from framechain.analysis.estimates import axis_text
from framechain.analysis.fault_model import FaultModel, Mode
from framechain.analysis.faults import LATENCY_BOUND_S, models_for
from framechain.analysis.fit import NOISE_FLOOR_M, fit_models, perturbation_of
from framechain.analysis.selection import MIN_BIC_GAIN, Objective, PointObjective, at_bound
from framechain.analysis.shares import MIN_SHARE
from framechain.arrays import BoolArray, FloatArray
from framechain.catalogue import Fault, HopName
from framechain.replay import CameraModel

#: Families with a size, the only ones a bound applies to (the others are discrete choices).
SIZED = (Fault.LATENCY, Fault.ROTATION_ERROR, Fault.TRANSLATION_ERROR, Fault.DEPTH_SCALE, Fault.INTRINSICS)
#: The largest size searched per family (in parameter units: s, rad, a scale's deviation from 1): past
#: these a fault is another family (a frame swap), or a scale a static target cannot tell from collapse.
MAX_SIZE = {Fault.LATENCY: LATENCY_BOUND_S, Fault.ROTATION_ERROR: np.pi / 2, Fault.TRANSLATION_ERROR: 0.5,
            Fault.DEPTH_SCALE: 0.8, Fault.INTRINSICS: 0.8}
#: Central-difference steps of the linearised search (s, rad, m, scale).
STEP = {Fault.LATENCY: 2e-3, Fault.ROTATION_ERROR: 1e-3, Fault.TRANSLATION_ERROR: 1e-3, Fault.DEPTH_SCALE: 1e-3,
        Fault.INTRINSICS: 1e-3}
#: Bisection steps between the last undetected and the first detected size (each halves a factor of 1.5).
BISECT = 6
#: A bound must also be detected at these multiples of it (up to 4x: twice the test's 2x), and the
#: search restarts past a failure at most this many times.
STABLE_FACTORS = (1.25, 1.5, 2.0, 3.0, 4.0)
STABLE_RESTARTS = 6
#: Times the injection check raises a bound (by half) when the refit does not find the fault.
INJECTION_RETRIES = 2
#: A body whose pose changes by less than this (m, and radians times a metre) over the observations is still.
STILL_M = 1e-4


@dataclass(frozen=True)
class Stage:
    """Where faults at ``hops`` are fitted: the objective (unweighted) over the observations with evidence.

    ``gate_m``: with logged hops a stage is only examined when its median departure exceeds this;
    ``rays``: bearing-only static targets; ``static``: the objective re-fits each target's position.
    """

    hops: tuple[HopName, ...]
    objective: Objective
    inputs: ChainInputs
    mode: Mode
    gate_m: float | None = None
    rays: bool = False
    #: the models to bound instead of the catalogue's (a rig: each camera's own, bounded per camera)
    models: tuple[FaultModel, ...] | None = None

    @property
    def static(self) -> bool:
        return not isinstance(self.objective, PointObjective)

    @classmethod
    def over_evidence(cls, hops: tuple[HopName, ...], objective: Objective, inputs: ChainInputs, mode: Mode,
                      *, gate_m: float | None = None, rays: bool = False,
                      models: tuple[FaultModel, ...] | None = None) -> Stage:
        """Only the observations the selection uses (a finite residual without any fault)."""
        if isinstance(objective, PointObjective):
            objective = replace(objective, weighting=None)
        rows = np.flatnonzero(np.isfinite(objective(inputs, Perturbation())).all(axis=1))
        if rows.size < len(inputs):
            objective, inputs = objective.take(rows), inputs.take(rows)
        return cls(hops, objective, inputs, mode, gate_m, rays, models)


@dataclass(frozen=True)
class _Noise:
    """What a fault's signal is measured against: the residual left by the findings."""

    residual: FloatArray  # (N, 3) with the findings applied
    departure: FloatArray  # (N, 3) with none (the logged-hop gate)
    n: int  # residuals as the BIC counts them (3 per observation)
    variance: float  # per residual, with the noise floor
    floor_m: float  # noise floor of a median (two standard errors)
    total_m: float  # median error before the findings
    gate_m: float | None
    #: the effect worth acting on (m): with it, a fault is detected only when it also moves the median error by this
    tolerance_m: float | None = None

    @classmethod
    def of(cls, stage: Stage, base: Perturbation) -> _Noise:
        residual = stage.objective(stage.inputs, base)
        departure = stage.objective(stage.inputs, Perturbation())
        finite = np.isfinite(residual).all(axis=1)
        r = residual[finite]
        n = max(int(r.size), 1)
        dist = np.linalg.norm(r, axis=1)
        floor = 2.0 * 1.2533 * float(np.std(dist)) / np.sqrt(dist.size) if dist.size else 0.0
        before = np.linalg.norm(departure, axis=1)
        before = before[np.isfinite(before)]
        total = float(np.median(before)) if before.size else 0.0
        return cls(residual, departure, n, float(np.sum(r * r)) / n + NOISE_FLOOR_M**2, floor, total, stage.gate_m)

    def needed_ss(self, model: FaultModel) -> float:
        """The sum of squared signal at which the model's BIC gain reaches :data:`MIN_BIC_GAIN`."""
        penalty = MIN_BIC_GAIN + model.n_params * np.log(max(self.n, 2)) + 2.0 * model.choice_penalty
        return float(self.n * self.variance * np.expm1(penalty / self.n))

    def detected(self, signal: FloatArray, model: FaultModel, theta: FloatArray | None = None) -> bool:
        """Whether a fault adding ``signal`` (N, 3) would be a finding at framechain's thresholds (a fault of
        parameters ``theta`` within its model's tolerance never is)."""
        if theta is not None and model.tolerance is not None and model.tolerance(theta):
            return False
        s = np.nan_to_num(signal)
        if float(np.sum(s * s)) < self.needed_ss(model):
            return False
        with_fault, without = np.linalg.norm(self.residual + s, axis=1), self._without
        both = np.isfinite(with_fault) & self._without_finite
        if not both.any():
            return False
        # The share a finding keeps is a difference of medians: another draw of the noise moves it by about
        # its standard error (paired), which the predicted share must clear as well as the rule.
        same_rows = self._without_median is not None and bool(np.array_equal(both, self._without_finite))
        median_without = self._without_median if same_rows else float(np.median(without[both]))
        share = float(np.median(with_fault[both]) - median_without)
        change = with_fault[both] - without[both]
        if model.camera is not None:
            # A rig camera's fault moves its own rows only, by sizes that differ from row to row: that spread is
            # the signal's shape, not noise. Its noise part is how far each moved row lands from the signal itself.
            change = np.minimum(np.abs(change), np.abs(with_fault[both] - np.linalg.norm(s[both], axis=1)))
        spread = 1.2533 * float(np.std(change)) / np.sqrt(both.sum())
        if share - spread <= 0 or (share - spread < MIN_SHARE * self.total_m and share - spread < self.floor_m):
            return False
        if self.tolerance_m is not None and _effect(share, with_fault, without, both, s, model) < self.tolerance_m:
            return False
        if self.gate_m is not None and self._departure_median <= self.gate_m:
            return _median_norm(self.departure + s) > self.gate_m
        return True

    # The residual without a fault is the same at every size a bound's search tries: measured once.
    @cached_property
    def _without(self) -> FloatArray:
        out: FloatArray = np.linalg.norm(self.residual, axis=1)
        return out

    @cached_property
    def _without_finite(self) -> BoolArray:
        return np.isfinite(self._without)

    @cached_property
    def _without_median(self) -> float | None:
        return float(np.median(self._without[self._without_finite])) if self._without_finite.any() else None

    @cached_property
    def _departure_median(self) -> float:
        return _median_norm(self.departure)


def _effect(share: float, with_fault: FloatArray, without: FloatArray, both: BoolArray, signal: FloatArray,
            model: FaultModel) -> float:
    """How much a fault moves the error, as a finding's effect is measured: the median's change (a rig camera's
    fault: on its own observations, the ones it moves, as :func:`~framechain.analysis.shares.own_effect`)."""
    if model.camera is None:
        return share
    moved = both & (np.linalg.norm(signal, axis=1) > 0)
    return float(np.median(with_fault[moved]) - np.median(without[moved])) if moved.any() else 0.0


def _median_norm(residual: FloatArray) -> float:
    d = np.linalg.norm(residual, axis=1)
    d = d[np.isfinite(d)]
    return float(np.median(d)) if d.size else 0.0


Found = Sequence[tuple[FaultModel, FloatArray]]


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
        noise = _Noise.of(stage, base)
        clean = _clean(stage, base)
        for fault, hop, variants in candidates:
            others = [(m, x) for m, x in mine if m.n_params and m.family != variants[0][0].family]
            results = [_bound_one(_Probe(stage, *clean, base, model, theta0, others), noise, tolerance_m)
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


# -- the signal of a fault, on noise-free observations ------------------------------------------
def _world_of(inputs: ChainInputs, pert: Perturbation, p_cam: FloatArray) -> FloatArray:
    p_world, ok = hop3(inputs, pert, hop2(inputs, pert, p_cam))
    p_world[~ok] = np.nan
    return p_world


def observations_for(inputs: ChainInputs, pert: Perturbation, world: FloatArray, *,
                     keep_depth: bool = False) -> ChainInputs:
    """The observations (pixels and depths) that the chain under ``pert`` turns into ``world`` (N, 3).

    Hops 2 and 3 are rigid for each observation (``world = o + A p_cam``, ``A`` orthogonal), so
    ``p_cam = A^T (world - o)``; its pixel comes from the camera model with the perturbation's
    intrinsics and its depth undoes the depth factor. Rows with no world point, or one behind the
    camera, keep theirs; ``keep_depth`` keeps every depth (rays at unit depth: only directions count).
    """
    n = len(inputs)
    origin = _world_of(inputs, pert, np.zeros((n, 3)))
    columns = [_world_of(inputs, pert, np.tile(np.eye(3)[k], (n, 1))) - origin for k in range(3)]
    a = np.stack(columns, axis=2)  # a[:, i, k]: world component i of camera axis k
    p_cam = np.einsum("nik,ni->nk", a, world - origin)
    ok = np.isfinite(p_cam).all(axis=1) & (np.nan_to_num(p_cam[:, 2]) > 1e-9)
    u, v = inputs.u.copy(), inputs.v.copy()
    factor = np.full(n, pert.depth_factor)
    if inputs.camera_index is None:
        _project(inputs.camera, pert.focal_scale, pert.principal_scale, p_cam, ok, u, v)
    else:  # a rig: each camera through its own model, with its own focal and depth scales
        for k, cam in enumerate(inputs.rig_cameras):
            delta = pert.cameras.get(k, CameraDelta())
            rows = inputs.camera_index == k
            _project(cam.camera, pert.focal_scale * delta.focal_scale, pert.principal_scale, p_cam, ok & rows, u, v)
            factor[rows] *= delta.depth_factor
    depth = inputs.depth_m.copy()
    if not keep_depth:
        depth[ok] = p_cam[ok, 2] / factor[ok]
    return replace(inputs, u=u, v=v, depth_m=depth)


def _project(camera: CameraModel, focal_scale: float, principal_scale: float, p_cam: FloatArray, rows: BoolArray,
             u: FloatArray, v: FloatArray) -> None:
    """Write the pixels of ``p_cam[rows]`` through ``camera`` with scaled intrinsics into ``u``, ``v``."""
    if not rows.any():
        return
    k_matrix = camera.K.copy()
    k_matrix[:2, :2] *= focal_scale
    k_matrix[:2, 2] *= principal_scale
    u[rows], v[rows] = replace(camera, K=k_matrix).project(p_cam[rows])


def _clean(stage: Stage, base: Perturbation) -> tuple[Objective, ChainInputs]:
    """The objective over the observations without their noise, and the rows to evaluate: each static
    target's sightings moved onto its fitted position (the objective's nuisance), a rig's sightings at one
    instant onto the point where they meet; logged points and references need none (their residual's
    change is the signal)."""
    objective = stage.objective
    if isinstance(objective, PointObjective):
        return objective, stage.inputs
    if isinstance(objective, CrossCameraObjective):
        return objective.over(observations_for(objective.rig, base, objective.consensus(base))), stage.inputs
    return objective, observations_for(stage.inputs, base, objective.points(stage.inputs, base),
                                       keep_depth=stage.rays)


def _params(model: FaultModel, theta0: FloatArray, direction: FloatArray, a: float) -> FloatArray:
    """The parameters of a fault of size ``a`` along ``direction`` (a scale multiplies: deviation ``a``)."""
    if model.fault in (Fault.DEPTH_SCALE, Fault.INTRINSICS):
        out: FloatArray = theta0 * (1.0 + a * direction)
        return out
    return theta0 + a * direction


@dataclass
class _Probe:
    """The signal of one model's fault on the noise-free observations, with the part the other findings'
    parameters could absorb (the selection refits them jointly) projected out."""

    stage: Stage
    objective: Objective  # the stage's, over the noise-free observations
    clean: ChainInputs
    base: Perturbation
    model: FaultModel
    theta0: FloatArray
    others: Found = ()  # the other findings with parameters, refitted beside a new fault

    def __post_init__(self) -> None:
        self.start = self.model.apply(self.base, self.theta0)
        self.at_zero = self.objective(self.clean, self.start)
        columns = [self._column(m, np.asarray(x, dtype=float), k) for m, x in self.others for k in range(m.n_params)]
        self.nuisance = np.linalg.qr(np.stack(columns, axis=1))[0] if columns else None

    def _raw(self, pert: Perturbation) -> FloatArray:
        out: FloatArray = self.objective(self.clean, pert) - self.at_zero
        out[~np.isfinite(out).all(axis=1)] = 0.0  # not evaluable at that offset: no evidence either way
        return out

    def _column(self, other: FaultModel, x: FloatArray, k: int) -> FloatArray:
        """The signal of another finding's k-th parameter (central differences): what its refit absorbs."""
        h = STEP[other.fault]
        step = np.zeros_like(x)
        step[k] = h
        plus, minus = self._raw(other.apply(self.start, x + step)), self._raw(other.apply(self.start, x - step))
        return ((plus - minus) / (2.0 * h)).reshape(-1)

    def signal(self, theta: FloatArray) -> FloatArray:
        out = self._raw(self.model.apply(self.base, theta))
        if self.nuisance is None:
            return out
        flat = out.reshape(-1)
        projected: FloatArray = (flat - self.nuisance @ (self.nuisance.T @ flat)).reshape(out.shape)
        return projected

    def jacobian(self) -> FloatArray:
        """(3N, k) by central differences at the start."""
        h = STEP[self.model.fault]
        cols = []
        for k in range(self.model.n_params):
            e = np.zeros(self.model.n_params)
            e[k] = 1.0
            plus = self.signal(_params(self.model, self.theta0, e, h))
            minus = self.signal(_params(self.model, self.theta0, e, -h))
            cols.append(((plus - minus) / (2.0 * h)).reshape(-1))
        return np.stack(cols, axis=1)


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


def _bound_one(probe: _Probe, noise: _Noise, tolerance_m: float = 0.0) -> _Result:
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


def _practical(probe: _Probe, noise: _Noise, direction: FloatArray, size: float, limit: float,
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


def _detected_at(probe: _Probe, noise: _Noise, direction: FloatArray, a: float) -> bool:
    """Detected at size ``a`` in both directions (the worse counts)."""
    thetas = [_params(probe.model, probe.theta0, s * direction, a) for s in (1.0, -1.0)]
    return all(noise.detected(probe.signal(theta), probe.model, theta) for theta in thetas)


def _smallest(probe: _Probe, noise: _Noise, direction: FloatArray, start: float, limit: float) -> float | None:
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


def _crossing(probe: _Probe, noise: _Noise, direction: FloatArray, a: float, limit: float) -> float | None:
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
    world = _world_of(inputs, model.apply(base, theta0), hop1(inputs, model.apply(base, theta0)))
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
    world = _world_of(rig, start, hop1(rig, start))
    return objective.over(observations_for(rig, faulty, world))


def refound(stage: Stage, noise: _Noise, base: Perturbation, model: FaultModel, theta0: FloatArray,
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
    if ok and noise.gate_m is not None and _median_norm(noise.departure) <= noise.gate_m:
        ok = _median_norm(objective(inputs, Perturbation())) > noise.gate_m
    return ok, fitted.params[-1]


def _checked(noise: _Noise, probe: _Probe, direction: FloatArray, size: float, blind: tuple[FloatArray, ...],
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
            theta = _params(model, theta0, sign * direction, size)
            ok, fitted = refound(stage, noise, probe.base, model, theta0, theta, probe.others)
            if ok:
                break
        if ok or attempt == INJECTION_RETRIES or size * 1.5 > MAX_SIZE[model.fault]:
            break
        size *= 1.5
    below = _params(model, theta0, direction, 0.98 * size)
    tolerated = model.tolerance is not None and model.tolerance(below)
    return _Result(model, size, direction, blind, best, _size_of(model, theta0, fitted, stage.mode),
                   _size_of(model, theta0, theta, stage.mode), ok, tolerated)


def _worse_sign(probe: _Probe, direction: FloatArray, size: float) -> float:
    """The direction whose fault of ``size`` adds the smaller signal."""
    energy = [float(np.sum(probe.signal(_params(probe.model, probe.theta0, s * direction, size)) ** 2))
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
def _assemble(stage: Stage, fault: Fault, hop: HopName, results: Sequence[_Result], noise: _Noise,
              tolerance_m: float = 0.0) -> Bound:
    """The family's bound: the worse of its models (intrinsics: two variants), with the sentence."""
    camera = results[0].model.camera or ""  # a rig camera's own models name it
    blind = [r for r in results if r.size is None]
    if blind:
        return Bound(hop, fault, False, None, _why_blind(stage, fault, hop), camera=camera)
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


def _noise_text(noise: _Noise) -> str:
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


def _why_blind(stage: Stage, fault: Fault, hop: HopName) -> str:
    """One sentence: why this family cannot be seen here."""
    inputs = stage.inputs
    if isinstance(stage.objective, CrossCameraObjective):  # a rig camera, measured against the others
        limit = MAX_SIZE[fault]
        largest = float(np.rad2deg(limit)) if fault == Fault.ROTATION_ERROR else limit
        name = "latency (stamp offset)" if fault == Fault.LATENCY else family_name(fault, hop)
        return (f"too weak a signal here: no {name} up to {size_text(fault, largest)} changes how the camera agrees "
                "with the others beyond framechain's thresholds")
    still = _still(inputs)
    if fault == Fault.LATENCY and (still.all() or (hop == HopName.BODY_TO_WORLD and _body_still(inputs))):
        return "the body does not move while the targets are seen: a pose taken at another time is the same pose"
    if stage.static and still.all():
        what = {Fault.LATENCY: "shifts nothing", Fault.ROTATION_ERROR: "only turns each target's fitted position",
                Fault.TRANSLATION_ERROR: "only moves each target's fitted position by as much",
                Fault.DEPTH_SCALE: "only moves each target's fitted position along its ray",
                Fault.INTRINSICS: "only moves each target's fitted position"}[fault]
        return f"the camera does not move relative to the static targets: {_article(family_name(fault, hop))} {what}"
    limit = MAX_SIZE[fault]
    largest = float(np.rad2deg(limit)) if fault == Fault.ROTATION_ERROR else limit
    if fault == Fault.TRANSLATION_ERROR and stage.static and _body_orientation_still(inputs):
        return ("the camera does not turn while the targets are seen: a mount moved in position only moves each "
                "target's fitted position by as much")
    return (f"too weak a signal here: no {family_name(fault, hop)} up to {size_text(fault, largest)} changes the "
            "error beyond framechain's thresholds")


def _article(noun: str) -> str:
    return f"{'an' if noun[:1] in 'aeiou' else 'a'} {noun}"


def _body_still(inputs: ChainInputs) -> bool:
    """Whether the body's recorded pose is the same at every observation."""
    if len(inputs) == 0:
        return True
    turned = np.abs(np.abs(np.einsum("ij,j->i", inputs.q_wb, inputs.q_wb[0])) - 1.0)
    return bool(np.linalg.norm(inputs.t_wb - inputs.t_wb[0], axis=1).max() < STILL_M and turned.max() < STILL_M**2)


def _body_orientation_still(inputs: ChainInputs) -> bool:
    """Whether the camera's orientation in the world is the same at every observation."""
    if len(inputs) == 0:
        return True
    origin = _world_of(inputs, Perturbation(), np.zeros((len(inputs), 3)))
    axes = [_world_of(inputs, Perturbation(), np.tile(np.eye(3)[k], (len(inputs), 1))) - origin for k in range(3)]
    turned = sum(np.linalg.norm(a - a[0], axis=1) for a in axes)
    return bool(np.nanmax(np.nan_to_num(turned, nan=np.inf)) < STILL_M)


def _still(inputs: ChainInputs) -> BoolArray:
    """Per observation: whether the camera's pose in the world is the same as at the first observation."""
    if len(inputs) == 0:
        return np.ones(0, dtype=bool)
    centre = _world_of(inputs, Perturbation(), np.zeros((len(inputs), 3)))
    ahead = _world_of(inputs, Perturbation(), np.tile([0.0, 0.0, 1.0], (len(inputs), 1)))
    moved = np.linalg.norm(centre - centre[0], axis=1) + np.linalg.norm(ahead - ahead[0], axis=1)
    out: BoolArray = np.nan_to_num(moved, nan=np.inf) < STILL_M
    return out


__all__ = ["SIZED", "Stage", "bounds", "bounds_candidates", "family_order", "observations_for", "refound",
           "without_evidence"]
