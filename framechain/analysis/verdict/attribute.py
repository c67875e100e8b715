"""Attribution: which hop, which fault, how big, and the fix.

:func:`attribute_replayed` attributes a replay already made
(:func:`~framechain.analysis.evidence.replayed.replay_chain`): a pure function of its inputs, the step
:func:`framechain.pipeline.run` (the one way in) takes after it has replayed and aligned a log once.
It picks the best evidence present (DESIGN.md "Evidence") and explains the error with the fault catalogue:

1. logged hops: the first hop whose logged output departs from the recomputed one (fed with the
   robot's own logged input) is classified; later hops are checked the same way;
2. a logged target: fault models are fitted to the raw inputs until they reproduce the target;
3. reference truth: per-hop corrections that remove the error against the reference are fitted,
   finding faults in the recorded data itself;
4. static targets alone: corrections that minimise the spread of each label's world points over
   short windows (or, with no depth, how far each label's rays pass from one point): static.py.

Models are chosen by forward selection on BIC (the simplest explanation wins, selection.py),
combined faults are fitted jointly, shares of the error are Shapley values over the faults found,
confidence is the BIC posterior weight of the chosen explanation against the alternatives, and
intervals come from a bootstrap over observations (shares.py).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from framechain.analysis.evidence.alignment import AlignedEvidence
from framechain.analysis.evidence.label_sizes import label_size_fits
from framechain.analysis.evidence.replayed import Replayed
from framechain.analysis.evidence.rig import rig_inputs, rig_level, unchecked_bounds
from framechain.analysis.evidence.rig_layout import RigLayout
from framechain.analysis.evidence.static import (
    RayObjective,
    StaticTargetError,
    WindowedSpreadObjective,
    static_objective,
)
from framechain.analysis.fit.least_squares import perturbation_of
from framechain.analysis.fit.selection import (
    HOP_DIVERGENCE_M,
    Objective,
    PointObjective,
    Selected,
    distances,
    hops_level,
    reweighted,
    select,
)
from framechain.analysis.fit.shares import (
    Bootstrapped,
    Found,
    drop_unexplaining,
    evidence_sentence,
    own_effect,
    refit_bootstrap,
    undetermined_because,
    weakened,
)
from framechain.analysis.model.chain import ChainInputs, Perturbation, evaluate
from framechain.analysis.model.estimates import format_estimate
from framechain.analysis.model.fault import FaultModel
from framechain.analysis.model.faults import LATENCY_BOUND_S, classify_rotation, models_for
from framechain.analysis.verdict.bounds import Stage, bounds, without_evidence
from framechain.analysis.verdict.checks import Bound, LabelTable, Undetermined, tolerance_text
from framechain.analysis.verdict.curves import curves, label_table
from framechain.analysis.verdict.findings import (
    AnalysisError,
    Attribution,
    Finding,
    Metric,
    Unattributed,
    as_undetermined,
    gate_by_effect,
)
from framechain.analysis.verdict.fixes import FixContext, fix_for
from framechain.arrays import FloatArray
from framechain.catalogue import Fault, HopName
from framechain.config.chain import ChainConfig
from framechain.geometry.camera import CameraModel
from framechain.progress import Progress, no_progress
from framechain.replay import ReplayResult
from framechain.timeline import PointRole, Timeline

Say = Progress  # a stage's name, and for counted stages how far into it


def attribute_replayed(
    replayed: Replayed,
    chain: ChainConfig,
    *,
    seed: int = 0,
    bootstrap: int = 30,
    progress: Say | None = None,
) -> Attribution:
    """Attribute the error of a replay (``replay_chain(timeline, chain)``); raises :class:`AnalysisError`
    with its :class:`Unattributed` reason when it cannot."""
    say: Say = progress or no_progress
    result = replayed.replay
    row = _camera_row(result, chain)
    inputs = (rig_inputs(replayed, chain) if chain.is_rig else
              ChainInputs.from_replay(result, replayed.buffer, CameraModel.from_table(replayed.timeline.cameras, row)))
    notes = [*replayed.buffer.warnings, *replayed.aligned.notes, *replayed.notes]
    level = _level(inputs, replayed.aligned.take(np.flatnonzero(result.replayed)), chain, replayed, say)
    recomputed_world = evaluate(inputs, Perturbation())[2]
    base = Attribution(
        source=dict(replayed.timeline.metadata.get("source", {"path": "", "format": "unknown"})), config=chain,
        replay=result, inputs=inputs, metric="none", error_before=np.full(len(inputs), np.nan),
        error_after=np.full(len(inputs), np.nan), hop_errors={}, evidence_points=np.full((len(inputs), 3), np.nan),
        corrected_world=recomputed_world, findings=(), seed=seed, aligned=replayed.aligned,
    )
    if level is None:
        return replace(base, notes=(*notes, "no evidence: log hop points, a target, a reference or declare a static "
                                    "target"), bounds=without_evidence(inputs))
    context = _fix_context(replayed.timeline, chain, result, row)
    assembled = _findings(level, inputs, context, np.random.default_rng(seed), bootstrap,
                          rays=replayed.bearing_only, say=say)
    found_bounds = (*bounds(level.stages, assembled.kept, say=say, no_depth=replayed.bearing_only,
                            tolerance_m=chain.tolerance_m), *level.unchecked)
    say("the error against each family's size, and per label")
    labels = _labels(result, level, inputs, assembled, chain, rays=replayed.bearing_only)
    # Corrections move the recomputed chain towards the truth; as-run faults describe what the
    # robot did, and the recomputed chain stays as it is.
    corrections = ("reference", "static_spread", "cross_camera")
    corrected = evaluate(inputs, assembled.combined)[2] if level.metric in corrections else recomputed_world
    findings, undetermined = judged(weakened(assembled.findings, found_bounds), chain.tolerance_m)
    misfit = unexplained_misfit(level.metric, assembled.error_before, assembled.error_after, chain.tolerance_m)
    return Attribution(
        source=base.source, config=chain, replay=result, inputs=inputs, metric=level.metric,
        error_before=assembled.error_before, error_after=assembled.error_after, hop_errors=level.hop_errors,
        evidence_points=level.evidence_world, corrected_world=corrected,
        findings=findings, undetermined=(*undetermined, *misfit), others_shift=assembled.others_shift, seed=seed,
        aligned=replayed.aligned, notes=(*notes, *level.notes, *assembled.notes), stage=level.stage,
        bounds=found_bounds, curves=curves(level.stages, assembled.kept, found_bounds), labels=labels, rig=level.rig,
    )


def _labels(result: ReplayResult, level: _Level, inputs: ChainInputs, assembled: _Assembled, chain: ChainConfig, *,
            rays: bool) -> LabelTable:
    """The per-label table; with static targets whose depth comes from declared sizes, each label's size checked."""
    labels = result.observations.label[result.replayed]
    declared = chain.evidence.tag_size_m
    if declared is None and chain.evidence.markers is not None:
        declared = chain.evidence.markers.size_m
    sizes = None
    if level.metric == "static_spread" and not rays and declared is not None and isinstance(
            level.objective, WindowedSpreadObjective):
        sizes = label_size_fits(inputs, assembled.combined, level.objective.groups, labels, declared)
    return label_table(labels, assembled.error_after, static=level.metric == "static_spread", sizes=sizes,
                       declared=declared)


def _camera_row(result: ReplayResult, chain: ChainConfig) -> int:
    """The row of the camera table most replayed observations were seen through; raises when there is
    nothing to attribute (no detections, none replayed, no camera model)."""
    if len(result) == 0:
        where = f" on {chain.topics.detections}" if chain.topics.detections else ""
        raise AnalysisError(f"the log has no detections{where} to replay (nothing to attribute); check the chain's "
                            "detections topic", Unattributed.NO_DETECTIONS)
    if not result.replayed.any():
        counts = result.counts()
        raise AnalysisError(f"no observation of camera {chain.frames.camera!r} could be replayed "
                            f"({counts['total']} total, rejected {counts['rejected']})", Unattributed.NOTHING_REPLAYED)
    row = result.main_camera_row()
    if row is None:
        raise AnalysisError(f"no CameraInfo for camera frame {chain.frames.camera!r}", Unattributed.NO_CAMERA_INFO)
    return row


# -- the evidence levels ----------------------------------------------------------------------
@dataclass(frozen=True)
class _Level:
    """The best evidence present: what the error is measured against and the faults selected to explain it."""

    metric: Metric
    objective: Objective  # the error is measured with it (world points, or the deepest logged hop)
    evidence_world: FloatArray  # (N, 3) world-frame evidence per replayed observation (NaN: none)
    selections: list[Selected]
    hop_errors: dict[str, FloatArray] = field(default_factory=dict)
    stage: str = "world"
    notes: tuple[str, ...] = ()
    #: where each hop's faults are fitted (what the bounds measure)
    stages: tuple[Stage, ...] = ()
    rig: RigLayout | None = None
    #: families no stage can bound, not observable (a rig's gauge cameras, and those compared with none)
    unchecked: tuple[Bound, ...] = ()


def _level(inputs: ChainInputs, evidence: AlignedEvidence, chain: ChainConfig, replayed: Replayed,
           say: Say) -> _Level | None:
    """Logged hops, else a logged target, else a reference, else static targets (None: no evidence)."""
    matched = {role: evidence.points(role)
               for role in (PointRole.HOP_CAMERA, PointRole.HOP_BODY, PointRole.HOP_WORLD, PointRole.TARGET)}
    if any(_present(matched[r]) for r in (PointRole.HOP_CAMERA, PointRole.HOP_BODY, PointRole.HOP_WORLD)):
        say("comparing the robot's logged hops with the recomputed ones")
        selections, hop_errors, deepest, examined = hops_level(inputs, matched, say)
        evidence_world = deepest.evidence if deepest.stage == "world" else np.full((len(inputs), 3), np.nan)
        stages = tuple(Stage.over_evidence(hops, objective, inputs, "as_run", gate_m=HOP_DIVERGENCE_M)
                       for hops, objective in examined)
        return _Level("logged_hops", deepest, evidence_world, selections, hop_errors, deepest.stage, stages=stages)
    every_hop = tuple(HopName)
    if _present(matched[PointRole.TARGET]):
        say("fitting fault models to the logged target")
        objective = PointObjective("world", matched[PointRole.TARGET])
        return _Level("target", objective, objective.evidence,
                      [select(models_for(inputs), objective, inputs, "as_run", say)],
                      stages=(Stage.over_evidence(every_hop, objective, inputs, "as_run"),))
    reference = _reference(evidence.points(PointRole.REFERENCE), chain)
    if reference is not None:
        say("fitting corrections against the reference")
        objective = PointObjective("world", reference)
        return _Level("reference", objective, reference,
                      [reweighted(select(models_for(inputs), objective, inputs, "correction", say))],
                      stages=(Stage.over_evidence(every_hop, objective, inputs, "correction"),))
    if inputs.rig_cameras:
        result = replayed.replay
        sources = {k: _camera_source(replayed.timeline, cam.frame) for k, cam in enumerate(inputs.rig_cameras)}
        rig = rig_level(inputs, chain, result.observations.label[result.replayed], say, camera_sources=sources)
        # Each camera's own models, measured against the others: its bounds are per camera.
        stage = Stage.over_evidence(every_hop, rig.objective, inputs, "correction", models=rig.candidates)
        return _Level("cross_camera", rig.objective, rig.evidence_world, [rig.selected], notes=rig.notes,
                      stages=(stage,), rig=rig.layout, unchecked=unchecked_bounds(rig.layout))
    if chain.evidence.static_target:
        return _static_level(inputs, chain, replayed, say)
    return None


def _camera_source(timeline: Timeline, frame: str) -> str:
    """Where a camera's model came from (a calibration file, a CameraInfo topic), "" when unknown."""
    rows = np.flatnonzero(timeline.cameras.frame == frame)
    return str(timeline.cameras.source[rows[0]]) if rows.size else ""


def _present(points: FloatArray) -> bool:
    return bool(np.isfinite(points).all(axis=1).any())


def _static_level(inputs: ChainInputs, chain: ChainConfig, replayed: Replayed, say: Say) -> _Level:
    """Static targets: corrections that minimise each object's spread (or how far its rays miss one point)."""
    say("minimising the spread of the static targets")
    result = replayed.replay
    labels = result.observations.label[result.replayed]
    rays = replayed.bearing_only
    try:
        static, notes_used = static_objective(inputs, labels, window_s=chain.evidence.static_window_s,
                                              bearing_only=rays, latency_bound_s=LATENCY_BOUND_S)
    except StaticTargetError as exc:  # observations were replayed: the pipeline says it as is
        raise AnalysisError(str(exc), Unattributed.STATIC_TARGET) from exc
    # Rays carry no depth: a depth scale cannot be seen (and residuals are across rays already).
    candidates = [m for m in models_for(inputs, blind=True) if not (rays and m.fault == Fault.DEPTH_SCALE)]
    selected = select(candidates, static, inputs, "correction", say)
    objective: Objective = static
    evidence_world = static.points(inputs, Perturbation())
    if isinstance(static, RayObjective):  # angles in metres at the range where the corrected rays meet
        objective = static.at_range_of(inputs, selected.fit.perturbation())
        # Where the corrected rays meet: a faulty chain's rays may meet far off, or not at all.
        evidence_world = static.points(inputs, selected.fit.perturbation())
    stage = Stage.over_evidence(tuple(HopName), static, inputs, "correction", rays=rays)
    return _Level("static_spread", objective, evidence_world, [reweighted(selected)], notes=tuple(notes_used),
                  stages=(stage,))


def _reference(matched: FloatArray, chain: ChainConfig) -> FloatArray | None:
    """The logged reference where any matched, else the declared reference point, else None."""
    if _present(matched):
        return matched
    if chain.evidence.reference_point is not None:
        return np.tile(np.asarray(chain.evidence.reference_point, dtype=float), (matched.shape[0], 1))
    return None


# -- the findings ----------------------------------------------------------------------------
@dataclass(frozen=True)
class _Assembled:
    findings: tuple[Finding, ...]
    error_before: FloatArray
    error_after: FloatArray
    combined: Perturbation  # every finding's fault applied at once
    notes: tuple[str, ...]  # the faults fitted but dropped, and why
    kept: tuple[tuple[FaultModel, FloatArray], ...] = ()  # each finding's model and parameters
    others_shift: tuple[FloatArray, ...] = ()  # per finding (in order): see Attribution.others_shift


def _findings(level: _Level, inputs: ChainInputs, context: FixContext, rng: np.random.Generator, draws: int, *,
              rays: bool, say: Say) -> _Assembled:
    """Every fault selected, with its Shapley share of the error, interval, evidence and fix (largest share
    first); the faults whose share cannot be told from noise become notes."""
    found: list[Found] = [
        (model, x, sel.confidences[i], sel.alternatives[i], sel)
        for sel in level.selections for i, (model, x) in enumerate(zip(sel.fit.models, sel.fit.params, strict=True))
    ]
    error_before = distances(level.objective(inputs, Perturbation()))
    total = float(np.nanmedian(error_before)) if np.isfinite(error_before).any() else 0.0
    say("splitting the error among the faults found (Shapley values)")
    found, shapley, dropped = drop_unexplaining(found, level.objective, inputs, total)
    combined = perturbation_of([f[0] for f in found], np.concatenate([f[1] for f in found]) if found else np.zeros(0))
    notes = []
    for model, x, share_m, why, sel in dropped:
        estimate = model.estimate(x, sel.mode, inputs)
        notes.append(f"{model.name} {format_estimate(estimate)} is no finding: its Shapley share of the median "
                     f"error is {share_m * 1e3:.2f} mm ({share_m / total if total > 0 else 0.0:.1%}), {why}; its fit "
                     "moved noise, not the error")
    findings: list[Finding] = []
    for k, (model, x, confidence, alternative, sel) in enumerate(found):
        fault = classify_rotation(model, x, sel.mode, inputs)
        estimate = model.estimate(x, sel.mode, inputs)
        fix = (model.fix(x, sel.mode, inputs) if model.fix is not None else
               fix_for(fault, model.hop, estimate, inputs, x, sel.mode, context=context))
        boot = refit_bootstrap(sel, model, rng, draws, say) if draws else Bootstrapped({})
        findings.append(Finding(
            fault=fault, hop=model.hop, estimate=estimate, interval=boot.interval,
            undetermined_because=undetermined_because(model, x, boot.interval, boot.at_edge),
            share=float(shapley[k] / total) if total > 0 else 0.0, error_m=float(shapley[k]),
            confidence=float(confidence),
            evidence=evidence_sentence(fault, model, level.metric, estimate, alternative, sel.mode,
                                       spread_m=(total, total - float(shapley[k])), rays=rays),
            fix=fix, model=model.name, camera=model.camera, own_effect_m=own_effect(found, k, level.objective, inputs),
        ))
    # What the other findings do to each world point, so that a picture can show one finding's effect alone.
    combined_world = evaluate(inputs, combined)[2]
    others = [combined_world - evaluate(inputs, perturbation_of([f[0]], f[1]))[2] for f in found]
    order = sorted(range(len(findings)), key=lambda k: findings[k].share, reverse=True)
    return _Assembled(tuple(findings[k] for k in order), error_before, distances(level.objective(inputs, combined)),
                      combined, tuple(notes), tuple((f[0], f[1]) for f in found),
                      others_shift=tuple(others[k] for k in order))


def judged(findings: tuple[Finding, ...], tolerance_m: float) -> tuple[tuple[Finding, ...], tuple[Undetermined, ...]]:
    """The findings with their fits judged: an undetermined fit gets no fix (and is listed, so that the verdict is
    inconclusive), a clear one whose effect is under the tolerance is a note."""
    undetermined = tuple(Undetermined(f"{f.fault.value} at {f.hop.value} ({format_estimate(f.estimate)})",
                                      "; ".join(f.undetermined_because), f.camera or "")
                         for f in findings if f.undetermined_because)
    judged_fits = tuple(as_undetermined(f, f.undetermined_because) if f.undetermined_because else f for f in findings)
    return gate_by_effect(judged_fits, tolerance_m, f"the {tolerance_text(tolerance_m)} tolerance (tolerance_m)"), \
        undetermined


#: Evidence whose noise is known, as a multiple of the tolerance: what the findings leave of the error beyond it is a
#: fault no model of the catalogue explains. The robot's own points recomputed from the same inputs are exact; a
#: reference (motion capture, a surveyed or declared point) is good to millimetres. A static spread or a rig's
#: disagreement carries the detector's own noise (centimetres for per-tag PnP far away): no such rule.
KNOWN_NOISE = {"logged_hops": 1.0, "target": 1.0, "reference": 10.0}
#: The findings leaving more than this share of the median error (and more than the noise) explain too little.
UNEXPLAINED_SHARE = 0.5
_AGAINST = {"logged_hops": "the robot's logged points", "target": "the logged target", "reference": "the reference"}


def unexplained_misfit(metric: Metric, before: FloatArray, after: FloatArray, tolerance_m: float
                       ) -> tuple[Undetermined, ...]:
    """The misfit the corrections do not explain, against evidence of known noise: undetermined when over that noise
    and over half the error (a remainder of noise is neither)."""
    if metric not in KNOWN_NOISE or not np.isfinite(before).any() or not np.isfinite(after).any():
        return ()
    median_before, median_after = float(np.nanmedian(before)), float(np.nanmedian(after))
    if median_after <= KNOWN_NOISE[metric] * tolerance_m or median_after <= UNEXPLAINED_SHARE * median_before:
        return ()
    return (Undetermined("the error", f"{median_after * 1e3:.1f} mm of its median {median_before * 1e3:.1f} mm "
                         f"against {_AGAINST[metric]} is left unexplained, more than that evidence's noise: none of "
                         "the catalogue's fault models explains it"),)


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


__all__ = ["AnalysisError", "Attribution", "Finding", "Unattributed", "attribute_replayed"]
