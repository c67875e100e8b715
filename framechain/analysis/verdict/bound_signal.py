"""The signal a fault of one family would add to this log's evidence, measured on noise-free copies of its
observations, against the noise the findings leave; and why a family the evidence cannot see is not observable.

:mod:`~framechain.analysis.verdict.bounds` searches these for the smallest fault framechain would make a finding (see
its docstring for the method); this module holds what it measures with: the :class:`Stage` a family is fitted at,
the :class:`Noise` a fault's signal must clear (the BIC gain, the share rule and, with a tolerance, the effect worth
acting on), the :class:`Probe` of one model's signal with the other findings' refit projected out, and the
observations a perturbed chain turns into given world points (:func:`observations_for`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from framechain.analysis.evidence.cross_camera import CrossCameraObjective
from framechain.analysis.fit.least_squares import NOISE_FLOOR_M
from framechain.analysis.fit.selection import MIN_BIC_GAIN, Objective, PointObjective
from framechain.analysis.fit.shares import MIN_SHARE
from framechain.analysis.model.chain import CameraDelta, ChainInputs, Perturbation, hop2, hop3
from framechain.analysis.model.fault import FaultModel, Mode
from framechain.analysis.model.faults import LATENCY_BOUND_S, TRANSLATION_BOUND_M
from framechain.analysis.verdict.checks import family_name, size_text
from framechain.arrays import BoolArray, FloatArray
from framechain.catalogue import Fault, HopName
from framechain.geometry.camera import CameraModel

#: Families with a size, the only ones a bound applies to (the others are discrete choices).
SIZED = (Fault.LATENCY, Fault.ROTATION_ERROR, Fault.TRANSLATION_ERROR, Fault.DEPTH_SCALE, Fault.INTRINSICS)
#: The largest size searched per family (in parameter units: s, rad, a scale's deviation from 1): past
#: these a fault is another family (a frame swap), or a scale a static target cannot tell from collapse.
MAX_SIZE = {Fault.LATENCY: LATENCY_BOUND_S, Fault.ROTATION_ERROR: np.pi / 2,
            Fault.TRANSLATION_ERROR: TRANSLATION_BOUND_M, Fault.DEPTH_SCALE: 0.8, Fault.INTRINSICS: 0.8}
#: Central-difference steps of the linearised search (s, rad, m, scale).
STEP = {Fault.LATENCY: 2e-3, Fault.ROTATION_ERROR: 1e-3, Fault.TRANSLATION_ERROR: 1e-3, Fault.DEPTH_SCALE: 1e-3,
        Fault.INTRINSICS: 1e-3}
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
class Noise:
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
    def of(cls, stage: Stage, base: Perturbation) -> Noise:
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
            return median_norm(self.departure + s) > self.gate_m
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
        return median_norm(self.departure)


def _effect(share: float, with_fault: FloatArray, without: FloatArray, both: BoolArray, signal: FloatArray,
            model: FaultModel) -> float:
    """How much a fault moves the error, as a finding's effect is measured: the median's change (a rig camera's
    fault: on its own observations, the ones it moves, as :func:`~framechain.analysis.fit.shares.own_effect`)."""
    if model.camera is None:
        return share
    moved = both & (np.linalg.norm(signal, axis=1) > 0)
    return float(np.median(with_fault[moved]) - np.median(without[moved])) if moved.any() else 0.0


def median_norm(residual: FloatArray) -> float:
    d = np.linalg.norm(residual, axis=1)
    d = d[np.isfinite(d)]
    return float(np.median(d)) if d.size else 0.0


Found = Sequence[tuple[FaultModel, FloatArray]]


# -- the signal of a fault, on noise-free observations ------------------------------------------
def world_of(inputs: ChainInputs, pert: Perturbation, p_cam: FloatArray) -> FloatArray:
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
    origin = world_of(inputs, pert, np.zeros((n, 3)))
    columns = [world_of(inputs, pert, np.tile(np.eye(3)[k], (n, 1))) - origin for k in range(3)]
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


def clean_observations(stage: Stage, base: Perturbation) -> tuple[Objective, ChainInputs]:
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


def fault_params(model: FaultModel, theta0: FloatArray, direction: FloatArray, a: float) -> FloatArray:
    """The parameters of a fault of size ``a`` along ``direction`` (a scale multiplies: deviation ``a``)."""
    if model.fault in (Fault.DEPTH_SCALE, Fault.INTRINSICS):
        out: FloatArray = theta0 * (1.0 + a * direction)
        return out
    return theta0 + a * direction


@dataclass
class Probe:
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
            plus = self.signal(fault_params(self.model, self.theta0, e, h))
            minus = self.signal(fault_params(self.model, self.theta0, e, -h))
            cols.append(((plus - minus) / (2.0 * h)).reshape(-1))
        return np.stack(cols, axis=1)


def why_blind(stage: Stage, fault: Fault, hop: HopName) -> str:
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
    origin = world_of(inputs, Perturbation(), np.zeros((len(inputs), 3)))
    axes = [world_of(inputs, Perturbation(), np.tile(np.eye(3)[k], (len(inputs), 1))) - origin for k in range(3)]
    turned = sum(np.linalg.norm(a - a[0], axis=1) for a in axes)
    return bool(np.nanmax(np.nan_to_num(turned, nan=np.inf)) < STILL_M)


def _still(inputs: ChainInputs) -> BoolArray:
    """Per observation: whether the camera's pose in the world is the same as at the first observation."""
    if len(inputs) == 0:
        return np.ones(0, dtype=bool)
    centre = world_of(inputs, Perturbation(), np.zeros((len(inputs), 3)))
    ahead = world_of(inputs, Perturbation(), np.tile([0.0, 0.0, 1.0], (len(inputs), 1)))
    moved = np.linalg.norm(centre - centre[0], axis=1) + np.linalg.norm(ahead - ahead[0], axis=1)
    out: BoolArray = np.nan_to_num(moved, nan=np.inf) < STILL_M
    return out


__all__ = ["MAX_SIZE", "SIZED", "STEP", "STILL_M", "Found", "Noise", "Probe", "Stage", "clean_observations",
           "fault_params", "median_norm", "observations_for", "why_blind", "world_of"]
