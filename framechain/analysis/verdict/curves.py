"""Curves and tables to check a verdict by eye: the error against each fitted family's size (the
time offsets searched for latency), and the per-label table with the labels to ignore.

Every curve is measured with the objective the family is fitted with, on this log's observations,
with the other findings applied: its median is the median error the findings' millimetres are
shares of, its root mean square what the fit minimises. A log of more than CURVE_ROWS observations
is measured on that many, evenly spread over it, as the fit's fine grid is: a curve is read by eye,
and each point of a latency curve is a pose lookup per observation (on a 10-minute log, 1 s of the
command for a difference in the third digit).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from framechain.analysis.evidence.label_sizes import SizeFit
from framechain.analysis.fit.least_squares import FINE_SUBSAMPLE, perturbation_of, subsample
from framechain.analysis.model.estimates import RotationEstimate, TranslationEstimate, estimate_scalars
from framechain.analysis.model.fault import FaultModel
from framechain.analysis.model.faults import LATENCY_BOUND_S
from framechain.analysis.verdict.bounds import Stage, bounds_candidates, family_order
from framechain.analysis.verdict.checks import DIRECTED, SIZE_KEYS, Bound, Curve, LabelRow, LabelTable, LabelVerdict
from framechain.arrays import FloatArray, StrArray
from framechain.catalogue import Fault

#: The time offsets of a latency curve: the whole range searched at this step (s), and finely around
#: the estimate and zero (over four bounds either side, at least 20 ms, in FINE_POINTS points).
COARSE_STEP_S = 0.02
FINE_HALF_WIDTH_S = 0.02
FINE_POINTS = 41
#: Points of the other families' curves, over 2.5 bounds (or 1.5 estimates) either side of no fault.
SIZE_POINTS = 41
#: Observations a curve is measured on, at most (evenly spread; the fit's fine grid uses as many).
CURVE_ROWS = FINE_SUBSAMPLE


def curves(stages: Sequence[Stage], found: Sequence[tuple[FaultModel, FloatArray]],
           bounds: Sequence[Bound]) -> tuple[Curve, ...]:
    """One curve per sized family and hop the stages fit (a family with two models: the one found, else
    the first)."""
    out = []
    for stage in stages:
        if stage.models is not None:  # a rig's cameras: bounded per camera, no curve per camera yet
            continue
        mine = [(m, x) for m, x in found if m.hop in stage.hops]
        base = perturbation_of([m for m, _ in mine], np.concatenate([x for _, x in mine]) if mine else np.zeros(0))
        objective, inputs = subsample(stage.objective, stage.inputs, CURVE_ROWS)
        for fault, hop, variants in bounds_candidates(stage, mine):
            model, theta0 = variants[0]
            bound = next((b for b in bounds if b.fault == fault and b.hop == hop), None)
            is_found = any(m.name == model.name for m, _ in mine)
            thetas, xs, axis = _sizes(stage, model, theta0, bound, is_found)
            medians, rms = [], []
            for theta in thetas:
                d = np.linalg.norm(objective(inputs, model.apply(base, theta)), axis=1)
                d = d[np.isfinite(d)]
                medians.append(float(np.median(d)) if d.size else float("nan"))
                rms.append(float(np.sqrt(np.mean(d * d))) if d.size else float("nan"))
            estimate = _key_value(model, theta0, stage, axis) if is_found else None
            out.append(Curve(hop, fault, SIZE_KEYS[fault], tuple(xs), tuple(medians), tuple(rms), estimate,
                             None if bound is None else bound.size, axis))
    return tuple(sorted(out, key=lambda c: family_order(c.fault, c.hop)))


def _sizes(stage: Stage, model: FaultModel, theta0: FloatArray, bound: Bound | None,
           is_found: bool) -> tuple[list[FloatArray], list[float], tuple[float, float, float] | None]:
    """The parameters along the curve, their x values in the estimate's key, and a rotation's axis."""
    size = bound.size if bound is not None and bound.size is not None else None
    if model.fault == Fault.LATENCY:
        half = max(4.0 * (size or 0.0), FINE_HALF_WIDTH_S)
        fine = np.linspace(-half, half, FINE_POINTS)
        values = np.unique(np.clip(np.concatenate([
            np.arange(-LATENCY_BOUND_S, LATENCY_BOUND_S + 1e-9, COARSE_STEP_S), fine, theta0[0] + fine]),
            -LATENCY_BOUND_S, LATENCY_BOUND_S).round(7))
        return [np.array([v]) for v in values], [float(v) for v in values], None
    if model.fault in DIRECTED:
        direction = (theta0 / np.linalg.norm(theta0) if is_found and np.linalg.norm(theta0) > 0
                     else np.asarray(bound.axis if bound is not None and bound.axis is not None else (0, 0, 1.0)))
        size_param = np.deg2rad(size or 1.0) if model.fault == Fault.ROTATION_ERROR else (size or 0.01)
        reach = max(2.5 * size_param, 1.5 * float(np.linalg.norm(theta0)))
        steps = np.linspace(-reach, reach, SIZE_POINTS)
        thetas = [t * direction for t in steps]
        # The axis the table names: the finding's, else the bound's (its sign as the bound states it).
        axis = (_fault_axis(model, reach * direction, stage) if is_found or bound is None or bound.axis is None
                else bound.axis)
        return thetas, [_key_value(model, t, stage, axis) for t in thetas], axis
    reach = max(2.5 * (size or 0.01), 1.5 * abs(float(theta0[0]) - 1.0))
    thetas = [np.array([1.0 + t]) for t in np.linspace(-reach, reach, SIZE_POINTS) if 1.0 + t > 0]
    return thetas, [_key_value(model, t, stage, None) for t in thetas], None


def _fault_axis(model: FaultModel, theta: FloatArray, stage: Stage) -> tuple[float, float, float]:
    """The axis (or direction) the estimate of ``theta`` names: the one the table shows, so the plot's sign is
    the table's."""
    estimate = model.estimate(theta, stage.mode, stage.inputs)
    if isinstance(estimate, TranslationEstimate):
        ox, oy, oz = (float(v) / max(estimate.distance_m, 1e-12) for v in estimate.offset_m)
        return ox, oy, oz
    assert isinstance(estimate, RotationEstimate)
    return estimate.axis


def _key_value(model: FaultModel, theta: FloatArray, stage: Stage, axis: tuple[float, float, float] | None) -> float:
    """The estimate of ``theta`` in its key; a rotation's angle signed about ``axis``."""
    estimate = model.estimate(theta, stage.mode, stage.inputs)
    if isinstance(estimate, RotationEstimate):
        sign = 1.0 if axis is None or float(np.dot(estimate.axis, axis)) >= 0 else -1.0
        return sign * estimate.angle_deg
    if isinstance(estimate, TranslationEstimate):
        return float(np.dot(estimate.offset_m, axis)) if axis is not None else estimate.distance_m
    return float(next(iter(estimate_scalars(estimate).values())))


# -- labels ----------------------------------------------------------------------------------
#: A static label whose median spread exceeds this many times the overall median (and the overall
#: median by MOVING_MARGIN_M) moves: it disagrees with itself as a whole, not by a few sightings.
MOVING_FACTOR = 3.0
MOVING_MARGIN_M = 1e-3
#: A label with at least this share of its sightings beyond OUTLIER_FACTOR times the overall median
#: (and MOVING_MARGIN_M past it), without moving as a whole, has outliers (misdetections).
OUTLIER_SHARE = 0.2
OUTLIER_FACTOR = 5.0


def label_table(labels: StrArray, errors: FloatArray, *, static: bool, sizes: Mapping[str, SizeFit] | None = None,
                declared: float | dict[str, float] | None = None) -> LabelTable:
    """Per label of the replayed observations: observations, those used (a finite error), the median
    and 90th percentile of the error after the findings, and a verdict.

    For static targets the verdict is ``static``, ``moving`` or ``outlier`` (or ``too few`` sightings
    to be used), and ``wrong size`` for a label that disagrees with itself only as a tag of another size would
    (``sizes``: each label's fit, :func:`~framechain.analysis.evidence.label_sizes.label_size_fits`; ``declared``: the
    chain's sizes); for other evidence ``agrees`` or ``outlier`` (the label disagrees with the evidence as a whole).
    """
    sizes = sizes or {}
    finite = np.isfinite(errors)
    if not finite.any():
        return LabelTable()
    overall = float(np.median(errors[finite]))
    names = sorted(set(np.asarray(labels, dtype=str).tolist()), key=_label_order)
    rows = []
    for name in names:
        mine = labels == name
        used = errors[mine & finite]
        if used.size == 0:
            rows.append(LabelRow(name, int(mine.sum()), 0, None, None, "too few"))
            continue
        spread, p90 = float(np.median(used)), float(np.percentile(used, 90))
        verdict = _verdict(spread, used, overall, static)
        fit = sizes.get(name)
        if verdict in ("moving", "outlier") and fit is not None and fit.wrong:
            rows.append(LabelRow(name, int(mine.sum()), int(used.size), spread, p90, "wrong size", fit.size_m,
                                 fit.declared_m))
            continue
        rows.append(LabelRow(name, int(mine.sum()), int(used.size), spread, p90, verdict))
    return LabelTable(tuple(rows), overall, declared)


def _verdict(spread: float, used: FloatArray, overall: float, static: bool) -> LabelVerdict:
    if spread > MOVING_FACTOR * overall and spread > overall + MOVING_MARGIN_M:
        return "moving" if static else "outlier"
    far = used > max(OUTLIER_FACTOR * overall, overall + MOVING_MARGIN_M)
    if far.mean() >= OUTLIER_SHARE and far.sum() >= 2:
        return "outlier"
    return "static" if static else "agrees"


def _label_order(label: str) -> tuple[int, float, str]:
    try:
        return (0, float(label), label)
    except ValueError:
        return (1, 0.0, label)


__all__ = ["curves", "label_table"]
