"""Attribution: which hop, which fault, how big, and the fix.

``attribute(timeline, chain)`` is a pure function of its inputs. It replays the log, picks the
best evidence present (DESIGN.md "Evidence") and explains the error with the fault catalogue:

1. logged hops: the first hop whose logged output departs from the recomputed one (fed with the
   robot's own logged input) is classified; later hops are checked the same way;
2. a logged target: fault models are fitted to the raw inputs until they reproduce the target;
3. reference truth: per-hop corrections that remove the error against the reference are fitted,
   finding faults in the recorded data itself;
4. static targets alone: corrections that minimise the spread of each label's world points over
   short windows (or, with no depth, how far each label's rays pass from one point): static.py.

Models are chosen by forward selection on BIC (the simplest explanation wins), combined faults
are fitted jointly, shares of the error are Shapley values over the faults found, confidence is
the BIC posterior weight of the chosen explanation against the alternatives, and intervals come
from a bootstrap over observations.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np

from framechain.analysis.alignment import AlignedEvidence, align_evidence
from framechain.analysis.chain_model import ChainInputs, Perturbation, evaluate, hop1, hop2, hop3
from framechain.analysis.estimates import Estimate, estimate_scalars, estimate_to_json, format_estimate
from framechain.analysis.fault_model import FaultModel, Mode
from framechain.analysis.faults import (
    LATENCY_BOUND_S,
    classify_rotation,
    models_for,
    rotation_starts,
)
from framechain.analysis.fit import Fit, fit_models, perturbation_of, posterior_weights
from framechain.analysis.fixes import FixContext, fix_for
from framechain.analysis.frame_swaps import swap_for_rotation
from framechain.analysis.static import (
    RayObjective,
    StaticObjective,
    StaticTargetError,
    is_bearing_only,
    static_objective,
    with_unit_depth,
)
from framechain.arrays import FloatArray, IntArray
from framechain.catalogue import Fault, HopName
from framechain.config.chain import ChainConfig
from framechain.replay import (
    REPLAYED,
    CameraModel,
    RejectReason,
    ReplayResult,
    TransformBuffer,
    camera_rows_for,
    replay,
    transform_points,
)
from framechain.timeline import FramechainError, PointRole, Timeline

Metric = Literal["logged_hops", "target", "reference", "static_spread", "none"]

#: A fault must lower the BIC by this much to be reported (strong evidence on Kass-Raftery's scale).
MIN_BIC_GAIN = 10.0
#: A hop is divergent when its median departure exceeds this (m).
HOP_DIVERGENCE_M = 2e-3
MAX_FAULTS = 3
#: A median error above this with no finding is called unexplained, not noise (m).
UNEXPLAINED_M = 0.02
SCHEMA = "framechain/attribution@1"


class AnalysisError(FramechainError):
    """The log could not be analysed (nothing replayed, no camera model)."""


@dataclass(frozen=True)
class Finding:
    """One fault found: the catalogue entry, its size, its share of the error and the fix."""

    fault: Fault
    hop: HopName
    estimate: Estimate
    interval: dict[str, list[float]]
    share: float
    error_m: float
    confidence: float
    evidence: str
    fix: str
    model: str

    def to_json(self) -> dict[str, Any]:
        return {
            "fault": self.fault.value,
            "hop": self.hop.value,
            "estimate": estimate_to_json(self.estimate),
            "interval": self.interval,
            "share": round(self.share, 4),
            "error_m": round(self.error_m, 6),
            "confidence": round(self.confidence, 4),
            "evidence": self.evidence,
            "fix": self.fix,
        }


@dataclass(frozen=True)
class Attribution:
    """The result of :func:`attribute`: counts, error, findings, and what they were computed from."""

    source: dict[str, Any]
    config: ChainConfig
    replay: ReplayResult
    inputs: ChainInputs
    metric: Metric
    error_before: FloatArray  # (N,) per replayed observation, against the evidence
    error_after: FloatArray  # (N,) once every finding is corrected
    hop_errors: dict[str, FloatArray]  # hop -> (N,) departure of the logged hop (logged-hops level)
    evidence_points: FloatArray  # (N, 3) world-frame evidence per replayed observation (NaN: none)
    corrected_world: FloatArray  # (N, 3) world points with the findings applied
    findings: tuple[Finding, ...]
    seed: int
    #: the logged evidence aligned to every observation of ``replay`` (all rows, in the chain's frames)
    aligned: AlignedEvidence
    notes: tuple[str, ...] = ()
    #: where the error is measured: the world point, or the deepest hop the robot logged
    stage: str = "world"

    def counts(self) -> dict[str, Any]:
        return self.replay.counts()

    def error_summary(self, errors: FloatArray | None = None) -> dict[str, Any]:
        e = self.error_before if errors is None else errors
        e = e[np.isfinite(e)]
        if e.size == 0:
            return {"metric": self.metric, "stage": self.stage, "median": None, "p95": None, "max": None}
        return {
            "metric": self.metric,
            "stage": self.stage,
            "median": round(float(np.median(e)), 6),
            "p95": round(float(np.percentile(e, 95)), 6),
            "max": round(float(e.max()), 6),
        }

    def hop_summary(self) -> list[dict[str, Any]]:
        """One row per hop: its own departure where the robot logged it, the time gaps of the samples
        it used (observation stamp minus the nearest sample of its stalest edge), stale count, and
        the error the findings put on it."""
        records = self.replay.hops
        replayed = records.status == REPLAYED
        rows = []
        for hop in HopName:
            sel = replayed & (records.hop == hop.value)
            gaps_ms = np.abs(records.gap_ns[sel]) * 1e-6
            departure = self.hop_errors.get(hop.value)
            dep = departure[np.isfinite(departure)] if departure is not None else np.zeros(0)
            rows.append({
                "hop": hop.value,
                "departure_m": None if dep.size == 0 else {
                    "median": round(float(np.median(dep)), 6), "p95": round(float(np.percentile(dep, 95)), 6),
                    "max": round(float(dep.max()), 6)},
                "gap_ms": None if gaps_ms.size == 0 else {
                    "median": round(float(np.median(gaps_ms)), 3), "max": round(float(gaps_ms.max()), 3)},
                "stale": int(records.stale[sel].sum()),
                "attributed_m": round(sum(f.error_m for f in self.findings if f.hop == hop), 6),
                "faults": [f.fault.value for f in self.findings if f.hop == hop],
            })
        return rows

    @property
    def verdict(self) -> str:
        """The answer in one sentence."""
        summary = self.error_summary()
        if self.metric == "none":
            return (
                "No evidence in this log to measure the chain against (no logged points, reference or static target)."
            )
        if not self.findings:
            return (
                f"No fault beyond noise: median error {summary['median'] * 1e3:.1f} mm against the "
                f"{self.metric.replace('_', ' ')}."
            )
        top = self.findings[0]
        more = f", plus {len(self.findings) - 1} more" if len(self.findings) > 1 else ""
        return (
            f"{top.fault.value} at {top.hop.value} ({format_estimate(top.estimate)}) explains "
            f"{top.share:.0%} of a median {summary['median'] * 1e3:.1f} mm error{more}."
        )

    def to_json(self) -> dict[str, Any]:
        """The attribution.json contract (schema framechain/attribution@1)."""
        counts = self.counts()
        frames = self.config.frames
        return {
            "schema": SCHEMA,
            "source": self.source,
            "frames": {"camera": frames.camera, "body": frames.body, "world": frames.world},
            "observations": counts,
            "error_m": self.error_summary(),
            "residual_m": self.error_summary(self.error_after),
            "verdict": self.verdict,
            "findings": [f.to_json() for f in self.findings],
            "hops": self.hop_summary(),
            "notes": list(self.notes),
        }


@dataclass(frozen=True)
class _PointObjective:
    """Residual of one hop's output (or the world point) against logged or reference points."""

    stage: Literal["camera", "body", "world"]
    evidence: FloatArray
    hop_input: FloatArray | None = None  # the robot's own logged point of an earlier stage
    input_stage: Literal["camera", "body"] | None = None  # which stage ``hop_input`` is the output of
    weighting: _RayWeighting | None = None

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

    def take(self, index: IntArray) -> _PointObjective:
        return replace(
            self, evidence=self.evidence[index], hop_input=None if self.hop_input is None else self.hop_input[index],
            weighting=None if self.weighting is None else self.weighting.take(index),
        )


@dataclass(frozen=True)
class _RayWeighting:
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

    def take(self, index: IntArray) -> _RayWeighting:
        return replace(self, rays_world=self.rays_world[index])


_Objective = _PointObjective | StaticObjective


@dataclass(frozen=True)
class _Selected:
    fit: Fit
    confidences: tuple[float, ...]
    alternatives: tuple[str, ...]  # next-best explanation at each step
    objective: _Objective
    mode: Mode
    inputs: ChainInputs  # the observations the fit used (those with evidence)


def attribute(
    timeline: Timeline,
    chain: ChainConfig,
    *,
    seed: int = 0,
    bootstrap: int = 30,
    progress: Callable[[str], None] | None = None,
) -> Attribution:
    """Replay ``timeline`` through ``chain`` and attribute its error (a pure function)."""
    say = progress or (lambda _msg: None)
    buffer = TransformBuffer.from_timeline(timeline)
    say("replaying observations")
    # A static target with no depth source at all is bearing-only: its observations are replayed as
    # rays (unit depth) and their spread measured as ray intersections (static.RayObjective).
    bearing_only = (chain.evidence.static_target and not chain.evidence_topics()
                    and chain.evidence.reference_point is None and is_bearing_only(timeline, chain.frames.camera))
    static_notes: list[str] = []
    if bearing_only:
        timeline, n_rays = with_unit_depth(timeline, chain.frames.camera)
        static_notes.append(f"bearing only: no depth for {chain.frames.camera} (none in the detections, no depth "
                            f"frames); its {n_rays} observations are replayed as rays at unit depth and the static "
                            "targets' spread measured as how far their rays pass from one point")
    result = replay(timeline, chain.frames, buffer=buffer, latency_budget_s=chain.latency_budget_s,
                    ignore_labels=chain.evidence.ignore_labels)
    ignored = int((result.status == RejectReason.IGNORED_LABEL.value).sum())
    if ignored:
        static_notes.append(f"ignore_labels: {ignored} observations of labels {list(chain.evidence.ignore_labels)} "
                            "rejected as ignored_label (declared moving)")
    if len(result) == 0:
        where = f" on {chain.topics.detections}" if chain.topics.detections else ""
        raise AnalysisError(f"the log has no detections{where} to replay (nothing to attribute); check the chain's "
                            "detections topic")
    if not result.replayed.any():
        counts = result.counts()
        raise AnalysisError(
            f"no observation of camera {chain.frames.camera!r} could be replayed "
            f"({counts['total']} total, rejected {counts['rejected']})"
        )
    camera_row = _camera_row(timeline, chain, result)
    camera = CameraModel.from_table(timeline.cameras, camera_row)
    inputs = ChainInputs.from_replay(result, buffer, camera)
    aligned = align_evidence(timeline.points, result.observations, chain.frames, buffer)
    evidence = aligned.take(np.flatnonzero(result.replayed))  # the rows of ``inputs``
    matched = {
        role: evidence.points(role)
        for role in (PointRole.HOP_CAMERA, PointRole.HOP_BODY, PointRole.HOP_WORLD, PointRole.TARGET)
    }
    reference = _reference(evidence.points(PointRole.REFERENCE), chain)
    source = dict(timeline.metadata.get("source", {"path": "", "format": "unknown"}))
    rng = np.random.default_rng(seed)
    recomputed_world = evaluate(inputs, Perturbation())[2]
    notes: list[str] = [*buffer.warnings, *aligned.notes, *static_notes]

    stage = "world"
    hops_present = [
        r
        for r in (PointRole.HOP_CAMERA, PointRole.HOP_BODY, PointRole.HOP_WORLD)
        if np.isfinite(matched[r]).all(axis=1).any()
    ]
    hop_errors: dict[str, FloatArray] = {}
    selections: list[_Selected] = []
    metric: Metric
    if hops_present:
        metric = "logged_hops"
        say("comparing the robot's logged hops with the recomputed ones")
        selections, hop_errors, deepest = _hops_level(inputs, matched, say)
        world_objective: _Objective = deepest
        evidence_world = deepest.evidence if deepest.stage == "world" else np.full((len(inputs), 3), np.nan)
        stage = deepest.stage
    elif np.isfinite(matched[PointRole.TARGET]).all(axis=1).any():
        metric = "target"
        say("fitting fault models to the logged target")
        evidence_world = matched[PointRole.TARGET]
        world_objective = _PointObjective("world", evidence_world)
        selections = [_select(models_for(inputs), world_objective, inputs, "as_run", say)]
    elif reference is not None:
        metric = "reference"
        say("fitting corrections against the reference")
        evidence_world = reference
        world_objective = _PointObjective("world", evidence_world)
        selections = [_reweighted(_select(models_for(inputs), world_objective, inputs, "correction", say))]
    elif chain.evidence.static_target:
        metric = "static_spread"
        say("minimising the spread of the static targets")
        labels = result.observations.label[result.replayed]
        try:
            static, notes_used = static_objective(inputs, labels, window_s=chain.evidence.static_window_s,
                                                  bearing_only=bearing_only, latency_bound_s=LATENCY_BOUND_S)
        except StaticTargetError as exc:
            raise AnalysisError(str(exc)) from exc  # observations were replayed: pipeline says it as is
        world_objective = static
        notes.extend(notes_used)
        evidence_world = static.points(inputs, Perturbation())
        # Rays carry no depth: a depth scale cannot be seen (and residuals are across rays already).
        candidates = [m for m in models_for(inputs, blind=True) if not (bearing_only and m.fault == Fault.DEPTH_SCALE)]
        selected = _select(candidates, world_objective, inputs, "correction", say)
        selections = [_reweighted(selected)]
        if isinstance(static, RayObjective):  # angles in metres at the range where the corrected rays meet
            world_objective = static.at_range_of(inputs, selected.fit.perturbation())
            # Where the corrected rays meet: a faulty chain's rays may meet far off, or not at all.
            evidence_world = static.points(inputs, selected.fit.perturbation())
    else:
        metric = "none"
        nan = np.full(len(inputs), np.nan)
        return Attribution(
            source=source,
            config=chain,
            replay=result,
            inputs=inputs,
            metric=metric,
            error_before=nan,
            error_after=nan,
            hop_errors={},
            evidence_points=np.full((len(inputs), 3), np.nan),
            corrected_world=recomputed_world,
            findings=(),
            seed=seed,
            aligned=aligned,
            notes=(*notes, "no evidence: log hop points, a target, a reference or declare a static target"),
        )

    # Every fault found, with its fitted parameters, as one combined perturbation.
    found: list[tuple[FaultModel, FloatArray, float, str, _Selected]] = []
    for sel in selections:
        for i, (model, x) in enumerate(zip(sel.fit.models, sel.fit.params, strict=True)):
            found.append((model, x, sel.confidences[i], sel.alternatives[i], sel))
    error_before = _distances(world_objective(inputs, Perturbation()))
    total = float(np.nanmedian(error_before)) if np.isfinite(error_before).any() else 0.0
    say("splitting the error among the faults found (Shapley values)")
    found, shapley, dropped = _drop_unexplaining(found, world_objective, inputs, total)
    combined = perturbation_of([f[0] for f in found], np.concatenate([f[1] for f in found]) if found else np.zeros(0))
    error_after = _distances(world_objective(inputs, combined))
    # Corrections move the recomputed chain towards the truth; as-run faults describe what the
    # robot did, and the recomputed chain stays as it is.
    corrected_world = evaluate(inputs, combined)[2] if metric in ("reference", "static_spread") else recomputed_world
    context = _fix_context(timeline, chain, result, camera_row)
    for model, x, share_m, why, sel in dropped:
        estimate = model.estimate(x, sel.mode, inputs)
        notes.append(f"{model.name} {format_estimate(estimate)} is no finding: its Shapley share of the median "
                     f"error is {share_m * 1e3:.2f} mm ({share_m / total if total > 0 else 0.0:.1%}), {why}; its fit "
                     "moved noise, not the error")
    findings: list[Finding] = []
    for k, (model, x, confidence, alternative, sel) in enumerate(found):
        fault = classify_rotation(model, x, sel.mode, inputs)
        estimate = model.estimate(x, sel.mode, inputs)
        interval = _bootstrap(sel, model, rng, bootstrap, say) if bootstrap else {}
        findings.append(
            Finding(
                fault=fault,
                hop=model.hop,
                estimate=estimate,
                interval=interval,
                share=float(shapley[k] / total) if total > 0 else 0.0,
                error_m=float(shapley[k]),
                confidence=float(confidence),
                evidence=_evidence_sentence(fault, model, metric, estimate, alternative, sel.mode,
                                            spread_m=(total, total - float(shapley[k])), rays=bearing_only),
                fix=fix_for(fault, model.hop, estimate, inputs, x, sel.mode, context=context),
                model=model.name,
            )
        )
    findings.sort(key=lambda f: f.share, reverse=True)
    return Attribution(
        source=source,
        config=chain,
        replay=result,
        inputs=inputs,
        metric=metric,
        error_before=error_before,
        error_after=error_after,
        hop_errors=hop_errors,
        evidence_points=evidence_world,
        corrected_world=corrected_world,
        findings=tuple(findings),
        seed=seed,
        aligned=aligned,
        notes=tuple(notes),
        stage=stage,
    )


# -- evidence ---------------------------------------------------------------------------------
def _camera_row(timeline: Timeline, chain: ChainConfig, result: ReplayResult) -> int:
    """The row of the camera table most replayed observations were seen through."""
    rows = camera_rows_for(timeline.cameras, chain.frames.camera, result.observations.stamp_ns[result.replayed])
    rows = rows[rows >= 0]
    if rows.size == 0:
        raise AnalysisError(f"no CameraInfo for camera frame {chain.frames.camera!r}")
    values, counts = np.unique(rows, return_counts=True)
    return int(values[np.argmax(counts)])


def _fix_context(timeline: Timeline, chain: ChainConfig, result: ReplayResult, row: int) -> FixContext:
    """Where the camera model (row ``row`` of the camera table) and the depths came from, so that a fix
    blames the right file or stream."""
    cameras = timeline.cameras
    # Calibration files' models are timeless (stamp 0, adapters/mounts.merge_file_cameras and the
    # LeRobot calibration); a recorded CameraInfo carries the stamp it was published at.
    from_file = int(cameras.stamp_ns[row]) == 0 and int(cameras.log_time_ns[row]) == 0
    detection_depth = result.observations.depth_m[result.replayed]
    markers = chain.evidence.markers
    return FixContext(
        camera_source=str(cameras.source[row]),
        camera_from_file=from_file and bool(str(cameras.source[row])),
        depth_from_images=bool(np.isnan(detection_depth).mean() > 0.5) if detection_depth.size else False,
        depth_from_tag_size=(chain.evidence.tag_size_m is not None
                             or (markers is not None and markers.size_m is not None)),
    )


def _reference(matched: FloatArray, chain: ChainConfig) -> FloatArray | None:
    """The logged reference where any matched, else the declared reference point, else None."""
    if np.isfinite(matched).all(axis=1).any():
        return matched
    if chain.evidence.reference_point is not None:
        return np.tile(np.asarray(chain.evidence.reference_point, dtype=float), (matched.shape[0], 1))
    return None


def _distances(residuals: FloatArray) -> FloatArray:
    out: FloatArray = np.linalg.norm(residuals, axis=1)
    return out


# -- the levels -------------------------------------------------------------------------------
def _hops_level(
    inputs: ChainInputs, matched: Mapping[PointRole, FloatArray], say: Callable[[str], None]
) -> tuple[list[_Selected], dict[str, FloatArray], _PointObjective]:
    """Logged hops: each logged stage fed with the robot's own logged input, compared with its output.

    A stage whose input was not logged is fed from the raw inputs, and the faults of every hop
    upstream of it are candidates. Returns the selections, each logged hop's departure, and the
    objective of the deepest logged stage (what the error is measured against).
    """
    stages = (
        ("camera", HopName.PIXEL_TO_CAMERA, matched[PointRole.HOP_CAMERA]),
        ("body", HopName.CAMERA_TO_BODY, matched[PointRole.HOP_BODY]),
        ("world", HopName.BODY_TO_WORLD, matched[PointRole.HOP_WORLD]),
    )
    selections: list[_Selected] = []
    hop_errors: dict[str, FloatArray] = {}
    previous: FloatArray | None = None  # the last logged stage's points: the next stage's input
    previous_stage: Literal["camera", "body"] | None = None
    upstream: list[HopName] = []
    deepest: _PointObjective | None = None
    for stage, hop, logged in stages:
        upstream.append(hop)
        if not np.isfinite(logged).all(axis=1).any():
            continue
        objective = _PointObjective(stage, logged, previous, previous_stage)  # type: ignore[arg-type]
        departure = _distances(objective(inputs, Perturbation()))
        hop_errors[hop.value] = departure
        if np.nanmedian(departure) > HOP_DIVERGENCE_M:
            say(f"classifying the departure at {hop.value}")
            sel = _select(models_for(inputs, tuple(upstream)), objective, inputs, "as_run", say)
            if sel.fit.models:
                selections.append(sel)
        previous, previous_stage, upstream, deepest = logged, stage, [], objective  # type: ignore[assignment]
    assert deepest is not None  # the caller checked that some hop was logged
    # The deepest stage, fed from the raw inputs, is what the robot's chain did end to end.
    return selections, hop_errors, _PointObjective(deepest.stage, deepest.evidence)


def _select(
    models: Sequence[FaultModel],
    objective: _Objective,
    inputs: ChainInputs,
    mode: Mode,
    say: Callable[[str], None],
) -> _Selected:
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
        base = current.perturbation()
        quick: list[tuple[Fit, FaultModel]] = []
        for candidate in candidates:  # each candidate alone on top of the faults already found
            model = (
                replace(candidate, starts=rotation_starts(inputs, mode))
                if candidate.name.startswith("rotation")
                else candidate
            )
            quick.append((fit_models([model], objective, inputs, base=base), model))
        # A fit that runs to the edge of its range explains by degenerating, not by a fault.
        quick = [(fit, model) for fit, model in quick if not _at_bound(model, fit.params[-1])]
        if not quick:
            break
        quick.sort(key=lambda item: item[0].bic)
        quick = _prefer_edge_swaps(quick, inputs)
        if current.models:  # refit the best few jointly with what was found before
            x_prev = np.concatenate(current.params)
            joint = []
            for fit, model in quick[:3]:
                x_start = np.concatenate([x_prev, fit.params[0]])
                joint.append((fit_models([*current.models, model], objective, inputs, x_start=x_start), model))
            joint = [(fit, model) for fit, model in joint if not _at_bound(model, fit.params[-1])]
            if not joint:
                break
            joint.sort(key=lambda item: item[0].bic)
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
    return _Selected(
        fit=current, confidences=tuple(confidences), alternatives=tuple(alternatives), objective=objective, mode=mode,
        inputs=inputs,
    )


def _prefer_edge_swaps(quick: list[tuple[Fit, FaultModel]], inputs: ChainInputs) -> list[tuple[Fit, FaultModel]]:
    """A fitted mount rotation that equals a path edge's rotation (within noise) is that edge skipped.

    When the best hypothesis is a free rotation and the frame swap whose rotation it matches fits
    about as well (within the BIC margin a finding must clear), the swap goes first: it names the
    frame to look up, where the rotation would name a 120 degree "calibration error".
    """
    if not quick or quick[0][1].fault != Fault.ROTATION_ERROR or quick[0][1].n_params == 0:
        return quick
    frame = swap_for_rotation(inputs, quick[0][0].params[-1])
    if frame is None:
        return quick
    name = f"frame_swap[camera:{frame}]"
    swap = next((i for i, (_fit, model) in enumerate(quick) if model.name == name), None)
    if swap is None or quick[swap][0].bic - quick[0][0].bic > MIN_BIC_GAIN:
        return quick
    return [quick[swap], *(item for i, item in enumerate(quick) if i != swap)]


def _at_bound(model: FaultModel, x: FloatArray) -> bool:
    """Whether a fitted parameter sits on a bound of its plausible range (to 0.1 %)."""
    if not model.lower or not model.plausibility_bounds:
        return False
    lo, hi, x = np.asarray(model.lower, float), np.asarray(model.upper, float), np.asarray(x, float)
    near_lo = np.isfinite(lo) & (x <= lo + 1e-3 * np.abs(lo) + 1e-12)
    near_hi = np.isfinite(hi) & (x >= hi - 1e-3 * np.abs(hi) - 1e-12)
    return bool((near_lo | near_hi).any())


def _reweighted(sel: _Selected) -> _Selected:
    """Refit the chosen faults with residuals whitened along the viewing rays (noisy evidence only).

    The selection is kept; only the parameters (and their bootstrap) use the weighted residuals.
    """
    if not sel.fit.models or all(m.n_params == 0 for m in sel.fit.models):
        return sel
    if isinstance(sel.objective, RayObjective):  # residuals across rays only: nothing to whiten
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
    objective = replace(sel.objective, weighting=_RayWeighting(rays, weight))
    refit = fit_models(sel.fit.models, objective, inputs, x_start=np.concatenate(sel.fit.params), grid=False)
    return replace(sel, fit=refit, objective=objective)


# -- shares, intervals, sentences ---------------------------------------------------------------
#: A fault that explains less than this fraction of the median error, and less than the noise floor
#: of a median (two standard errors of the residual's median), is not a finding: its fit moved noise.
MIN_SHARE = 0.01


def _drop_unexplaining(
    found: list[tuple[FaultModel, FloatArray, float, str, _Selected]],
    objective: _Objective,
    inputs: ChainInputs,
    total: float,
) -> tuple[
    list[tuple[FaultModel, FloatArray, float, str, _Selected]],
    list[float],
    list[tuple[FaultModel, FloatArray, float, str, _Selected]],
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
    dropped: list[tuple[FaultModel, FloatArray, float, str, _Selected]] = []
    while True:
        shapley = _shapley(kept, objective, inputs)
        if not kept:
            return kept, shapley, dropped
        combined = perturbation_of([f[0] for f in kept], np.concatenate([f[1] for f in kept]))
        residual = _distances(objective(inputs, combined))
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


def _shapley(
    found: Sequence[tuple[FaultModel, FloatArray, float, str, _Selected]], objective: _Objective, inputs: ChainInputs
) -> list[float]:
    """Shapley values of the median error explained, over the faults found (2^k replays)."""
    k = len(found)
    if k == 0:
        return []
    cache: dict[frozenset[int], float] = {}

    def error(subset: frozenset[int]) -> float:
        if subset not in cache:
            chosen = [found[i] for i in sorted(subset)]
            pert = perturbation_of(
                [c[0] for c in chosen], np.concatenate([c[1] for c in chosen]) if chosen else np.zeros(0)
            )
            cache[subset] = float(np.nanmedian(_distances(objective(inputs, pert))))
        return cache[subset]

    values = []
    for i in range(k):
        others = [j for j in range(k) if j != i]
        phi = 0.0
        for size in range(k):
            weight = math.factorial(size) * math.factorial(k - size - 1) / math.factorial(k)
            for subset in itertools.combinations(others, size):
                s = frozenset(subset)
                phi += weight * (error(s) - error(s | {i}))
        values.append(phi)
    return values


def _bootstrap(
    sel: _Selected,
    model: FaultModel,
    rng: np.random.Generator,
    draws: int,
    say: Callable[[str], None],
) -> dict[str, list[float]]:
    """95% intervals of the model's scalar estimates over observation resamples."""
    if model.n_params == 0:
        return {}
    say(f"bootstrapping {model.name} ({draws} resamples)")
    x_fit = np.concatenate(sel.fit.params)
    index = [m.name for m in sel.fit.models].index(model.name)
    samples: dict[str, list[float]] = {}
    inputs = sel.inputs
    n = len(inputs)
    for _ in range(draws):
        idx = rng.integers(0, n, n)
        refit = fit_models(sel.fit.models, sel.objective.take(idx), inputs.take(idx), x_start=x_fit, grid=False)
        scalars = estimate_scalars(model.estimate(refit.params[index], sel.mode, inputs))
        for key, value in scalars.items():
            samples.setdefault(key, []).append(float(value))
    return {
        k: [round(float(np.percentile(v, 2.5)), 6), round(float(np.percentile(v, 97.5)), 6)] for k, v in samples.items()
    }


def _evidence_sentence(
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
    }[metric]
    side = "recorded data" if mode == "correction" else "chain that produced the evidence"
    return (
        f"With {fault.value} ({format_estimate(estimate)}) in the {side}, {where}; "
        f"next-best explanation: {alternative}."
    )
