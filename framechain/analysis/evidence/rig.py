"""A rig's evidence level: every camera's observations at once, measured against the other cameras'.

:func:`rig_inputs` turns a rig's replay into one :class:`~framechain.analysis.model.chain.ChainInputs`
(each row knows its camera); :func:`rig_level` builds the cross-camera objective
(:mod:`~framechain.analysis.evidence.cross_camera`), works out which cameras are compared and which set the gauge
(:mod:`~framechain.analysis.evidence.rig_layout`) and selects the per-camera faults
(:mod:`~framechain.analysis.model.rig_faults`) that explain the disagreement, with BIC forward selection like
every other level. The bounds of a rig (what each camera's evidence can show) follow from the same
objective and models: each model is a function of its own camera's parameters only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from framechain.analysis.evidence.cross_camera import CrossCameraObjective, PairIndex, camera_ranges, pair_index
from framechain.analysis.evidence.replayed import Replayed
from framechain.analysis.evidence.rig_layout import PairLines, RigLayout, RigPose, camera_groups, count_links
from framechain.analysis.evidence.static import (
    DEFAULT_WINDOW_S,
    MIN_KEPT_SHARE,
    StaticGroups,
    latency_margin,
    static_groups,
)
from framechain.analysis.fit.least_squares import fit_models
from framechain.analysis.fit.selection import Selected, select
from framechain.analysis.model.chain import ChainInputs, Perturbation
from framechain.analysis.model.fault import FaultModel
from framechain.analysis.model.faults import LATENCY_BOUND_S, models_for
from framechain.analysis.model.rig_faults import ROTATION_TOLERANCE_DEG, rig_models
from framechain.analysis.verdict.checks import Bound
from framechain.analysis.verdict.findings import AnalysisError, Unattributed
from framechain.arrays import BoolArray, FloatArray, IntArray, StrArray
from framechain.catalogue import Fault, HopName
from framechain.config.chain import ChainConfig
from framechain.geometry.camera import CameraModel
from framechain.progress import Progress

#: A camera's mount turned less than this from the others' (degrees) is not worth a note.
NOTED_DEG = 0.1


def rig_inputs(replayed: Replayed, chain: ChainConfig) -> ChainInputs:
    """The rig's replayed observations, each with its camera (the cameras with a model and a replayed
    observation, in the chain's order)."""
    result = replayed.replay
    cameras = replayed.timeline.cameras
    models: dict[str, CameraModel] = {}
    for frame in chain.camera_frames():
        rows = result.camera_row[result.replayed & (result.observations.camera_frame == frame)]
        rows = rows[rows >= 0]
        if rows.size:
            values, counts = np.unique(rows, return_counts=True)
            models[frame] = CameraModel.from_table(cameras, int(values[np.argmax(counts)]))
    if not models:
        raise AnalysisError("no camera of the rig has a replayed observation with a camera model",
                            Unattributed.NO_CAMERA_INFO)
    return ChainInputs.from_rig_replay(result, replayed.buffer, models)


def rig_pose(inputs: ChainInputs, chain: ChainConfig) -> RigPose:
    """How the rig is placed: no pose, a fixed one (body = world, or static edges), or a moving one."""
    if not chain.has_pose:
        return RigPose.NONE
    path = inputs.buffer.path(inputs.frames.world, inputs.frames.body)
    return RigPose.MOVING if any(not hop.is_static for hop in path.hops) else RigPose.FIXED


@dataclass(frozen=True)
class RigLevel:
    """The rig's evidence: its objective, the faults selected, what each observation is measured against."""

    objective: CrossCameraObjective
    selected: Selected
    evidence_world: FloatArray
    layout: RigLayout
    notes: tuple[str, ...]
    candidates: tuple[FaultModel, ...] = ()  # every per-camera model (what the bounds measure)


@dataclass(frozen=True)
class RigEvidence:
    """What a rig's cameras can be measured against: the objective, the layout (groups, gauges, what cannot be
    seen) and the fault models each camera can be fitted with. Each model changes its own camera only, so the
    objective's Jacobian in one model's parameters, profiled over the others, bounds that camera's fault."""

    objective: CrossCameraObjective
    layout: RigLayout
    candidates: tuple[FaultModel, ...]
    notes: tuple[str, ...]


def rig_evidence(inputs: ChainInputs, chain: ChainConfig, labels: StrArray, *,
                 camera_sources: dict[int, str] | None = None) -> RigEvidence:
    """The rig's objective, layout and per-camera models (``labels``: the replayed observations' labels, the rows
    of ``inputs``); raises :class:`AnalysisError` when no two cameras saw anything alike."""
    pose = rig_pose(inputs, chain)
    moving = np.isin(labels, list(chain.evidence.moving_labels))
    static_rows = ~moving if (pose is not RigPose.NONE and chain.evidence.static_target) else np.zeros_like(moving)
    notes: list[str] = []
    static = _static_groups(inputs, labels, static_rows, chain, pose, notes)
    pairs = pair_index(inputs, labels, ~static_rows)
    objective = CrossCameraObjective(inputs, static, pairs, camera_ranges(inputs),
                                     timeless_pose=pose is not RigPose.MOVING)
    layout = _layout(inputs, pose, static, pairs)
    used = objective(inputs, Perturbation())
    if not np.isfinite(used).all(axis=1).any():
        raise AnalysisError(_nothing_compared(inputs, pose), Unattributed.STATIC_TARGET)
    mounts = {m.child: m for m in chain.mounts}
    candidates: list[FaultModel] = rig_models(inputs, layout, mounts, camera_sources or {})
    if pose is RigPose.MOVING:  # the rig's pose itself late or early
        candidates += [m for m in models_for(inputs, blind=True)
                       if m.fault == Fault.LATENCY and m.hop == HopName.BODY_TO_WORLD]
    notes.insert(0, f"rig: {int(np.isfinite(used).all(axis=1).sum())} of {len(inputs)} replayed observations "
                    f"compared ({int(static.used.sum())} against static objects, {_anchors(pairs)} with another "
                    "camera at the same instant)")
    return RigEvidence(objective, layout, tuple(candidates), tuple(notes))


def rig_level(inputs: ChainInputs, chain: ChainConfig, labels: StrArray, say: Progress, *,
              camera_sources: dict[int, str] | None = None) -> RigLevel:
    """Select the per-camera faults that explain how the rig's cameras disagree (``labels``: the replayed
    observations' labels, the rows of ``inputs``)."""
    say("comparing the rig's cameras")
    evidence = rig_evidence(inputs, chain, labels, camera_sources=camera_sources)
    objective, layout = evidence.objective, evidence.layout
    selected = select(list(evidence.candidates), objective, inputs, "correction", say)
    notes = [*evidence.notes, *_left_within_tolerance(list(evidence.candidates), selected, objective, inputs, layout)]
    layout = replace(layout, lines=_pair_lines(objective, inputs))
    return RigLevel(objective, selected, objective.points(inputs, Perturbation()), layout,
                    (*notes, *layout.notes()), evidence.candidates)


#: The per-camera families a bound is given for (the sized ones of :func:`rig_models`).
CAMERA_FAMILIES = ((Fault.LATENCY, HopName.BODY_TO_WORLD), (Fault.ROTATION_ERROR, HopName.CAMERA_TO_BODY),
                   (Fault.TRANSLATION_ERROR, HopName.CAMERA_TO_BODY), (Fault.DEPTH_SCALE, HopName.PIXEL_TO_CAMERA),
                   (Fault.INTRINSICS, HopName.PIXEL_TO_CAMERA))


def unchecked_bounds(layout: RigLayout) -> tuple[Bound, ...]:
    """The cameras whose own faults the rig's evidence cannot bound, each family not observable with why: a
    group's gauge (its fault shows on the other camera of its pair, bounded there) or a camera compared with
    none (alone: without a moving pose its own sightings show nothing of its chain)."""
    out: list[Bound] = []
    for k, frame in enumerate(layout.frames):
        if layout.checkable(k):
            continue
        group = layout.group_of(k)
        if len(group.cameras) == 2:
            other = layout.frames[next(c for c in group.cameras if c != k)]
            why = (f"{frame} sets the gauge of its pair with {other}: a fault of {frame} against {other} shows as "
                   f"the opposite fault on {other} (bounded there); neither can be checked against the world")
        else:
            why = (f"no other camera saw what {frame} saw at the same instant or place, and without a moving pose its "
                   "own sightings show nothing of its chain")
        out += [Bound(hop, fault, False, None, why, camera=frame) for fault, hop in CAMERA_FAMILIES]
    return tuple(out)


def _left_within_tolerance(candidates: list[FaultModel], selected: Selected, objective: CrossCameraObjective,
                           inputs: ChainInputs, layout: RigLayout) -> list[str]:
    """How far each checked camera's mount still turns from the others' once the findings are applied, when that
    is within the tolerance (no finding, but the disagreement the calibration leaves, measured)."""
    out: list[str] = []
    found = {m.name for m in selected.fit.models}
    base = selected.fit.perturbation()
    index = _camera_index(inputs)
    before = np.linalg.norm(objective(inputs, base), axis=1)
    for model in candidates:
        if model.camera is None or not model.name.startswith("mount_rotation") or model.name in found:
            continue
        fit = fit_models([model], objective, inputs, base=base, grid=False)
        if model.tolerance is None or not model.tolerance(fit.params[0]):
            continue
        k = layout.frames.index(model.camera)
        mine = (index == k) & np.isfinite(before)
        after = np.linalg.norm(objective(inputs, model.apply(base, fit.params[0])), axis=1)
        angle = float(np.rad2deg(np.linalg.norm(fit.params[0])))
        if angle < NOTED_DEG:
            continue
        out.append(f"rig: {model.camera}'s mount agrees with the other cameras' to {angle:.2f} deg (turning it so "
                   f"would take the median disagreement of its observations from {np.median(before[mine]) * 1e3:.1f} "
                   f"to {np.nanmedian(after[mine]) * 1e3:.1f} mm): within the {ROTATION_TOLERANCE_DEG:g} deg a "
                   "cross-check of per-tag detections can pin on a mount (a principal point or lens model a few pixels "
                   "off looks the same), so no finding")
    return out


def _anchors(pairs: PairIndex) -> int:
    return int(np.unique(pairs.anchor).size)


def _camera_index(inputs: ChainInputs) -> IntArray:
    assert inputs.camera_index is not None
    return inputs.camera_index


def _static_groups(inputs: ChainInputs, labels: StrArray, rows: BoolArray, chain: ChainConfig, pose: RigPose,
                   notes: list[str]) -> StaticGroups:
    """(label, window) objects over the static rows; on a fixed rig only those seen by several cameras."""
    usable = rows.copy()
    if pose is RigPose.MOVING and rows.any():
        inside = latency_margin(inputs, LATENCY_BOUND_S)
        if inside[rows].mean() >= MIN_KEPT_SHARE:
            usable &= inside
    window = chain.evidence.static_window_s or DEFAULT_WINDOW_S
    groups = static_groups(labels, inputs.stamp_ns, window_s=window, usable=usable)
    if pose is RigPose.FIXED and groups.n_groups:
        cameras_of = _cameras_per_group(groups, _camera_index(inputs), len(inputs.rig_cameras))
        several = cameras_of.sum(axis=1) >= 2
        dropped = int((groups.used & ~several[np.maximum(groups.group, 0)]).sum())
        groups = groups.keep(groups.used & several[np.maximum(groups.group, 0)])
        if dropped:
            notes.append(f"rig: {dropped} observations of static objects seen by one camera only are not used (a "
                         "fixed camera over a fixed tag shows nothing of its own chain)")
    return groups


def _cameras_per_group(groups: StaticGroups, index: IntArray, n_cameras: int) -> BoolArray:
    """(G, K): which cameras saw each static object."""
    present = np.zeros((max(groups.n_groups, 1), max(n_cameras, 1)), dtype=bool)
    used = groups.used
    present[groups.group[used], index[used]] = True
    return present


def _layout(inputs: ChainInputs, pose: RigPose, static: StaticGroups, pairs: PairIndex) -> RigLayout:
    """Which cameras are compared with which, their groups and gauges."""
    index = _camera_index(inputs)
    k = len(inputs.rig_cameras)
    one_way = index[pairs.anchor] < pairs.partner  # each instant once
    links = count_links(index[pairs.anchor][one_way], pairs.partner[one_way])
    if static.n_groups:
        present = _cameras_per_group(static, index, k)
        for a in range(k):
            for b in range(a + 1, k):
                shared = int((present[:, a] & present[:, b]).sum())
                if shared:
                    links[(a, b)] = links.get((a, b), 0) + shared
    compared = np.zeros(len(inputs), dtype=bool)
    compared[pairs.anchor] = True
    compared |= static.used
    return RigLayout(
        frames=tuple(c.frame for c in inputs.rig_cameras), pose=pose,
        observations=tuple(int((index == c).sum()) for c in range(k)),
        compared=tuple(int((compared & (index == c)).sum()) for c in range(k)),
        links=links, groups=camera_groups(k, links, pose),
    )


def _pair_lines(objective: CrossCameraObjective, inputs: ChainInputs) -> PairLines:
    """The same-instant comparisons as recorded, once per pair of sightings (to draw)."""
    anchor, partner, points = objective.partners(Perturbation())
    index = _camera_index(inputs)
    once = index[anchor] < partner
    frames = tuple(c.frame for c in inputs.rig_cameras)
    return PairLines(obs_id=inputs.obs_id[anchor[once]], partner_frame=tuple(frames[p] for p in partner[once]),
                     partner_point=points[once])


def _nothing_compared(inputs: ChainInputs, pose: RigPose) -> str:
    what = ("no label was seen by two cameras at the same instant" if pose is RigPose.NONE else
            "no label was seen by two cameras at the same instant, and no static object by several cameras")
    return (f"rig: {what} among {len(inputs)} replayed observations of {len(inputs.rig_cameras)} cameras: nothing "
            "to compare the cameras with; declare evidence.static_target (with a pose) or record the cameras "
            "seeing the same tags")


__all__ = ["CAMERA_FAMILIES", "RigEvidence", "RigLevel", "rig_evidence", "rig_inputs", "rig_level", "rig_pose",
           "unchecked_bounds"]
