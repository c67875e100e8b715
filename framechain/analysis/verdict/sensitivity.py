"""What a finding means on this episode: the robot's speed at each observation (a latency grows with it)
and how fast the fault found hurts as it grows (the tilt lab for whatever was found)."""

from __future__ import annotations

import numpy as np

from framechain.analysis.fit.least_squares import FINE_SUBSAMPLE, even_rows, perturbation_of
from framechain.analysis.model.chain import Perturbation, evaluate
from framechain.analysis.model.estimates import LatencyEstimate, RotationEstimate, ScaleEstimate
from framechain.analysis.model.faults import models_for
from framechain.analysis.verdict.findings import Attribution, Finding
from framechain.arrays import FloatArray
from framechain.catalogue import Fault


def robot_speed(result: Attribution, window_s: float = 0.05) -> FloatArray:
    """Body speed in the world frame (m/s) at each replayed observation, by central differences."""
    inputs = result.inputs
    t_before, _, ok_b = inputs.world_from_body(-window_s, None)
    t_after, _, ok_a = inputs.world_from_body(window_s, None)
    speed = np.linalg.norm(t_after - t_before, axis=1) / (2 * window_s)
    speed[~(ok_a & ok_b)] = np.nan
    out: FloatArray = speed
    return out


def sensitivity(result: Attribution, finding: Finding, steps: int = 31) -> tuple[FloatArray, FloatArray, str]:
    """Median world error as the finding's fault grows from nothing to 1.5x its estimate.

    The tilt lab for whatever was found: how fast does this fault hurt at this robot's depths
    and speeds? Returns (magnitudes, median error in m, axis label). A median read by eye: on a long
    log, over FINE_SUBSAMPLE observations evenly spread over it (each step of a latency looks up
    every observation's pose).
    """
    model = next((m for m in models_for(result.inputs) if m.name == finding.model), None)
    if model is None or model.n_params == 0:
        return np.zeros(0), np.zeros(0), ""
    x_full = _params_of(finding, model.n_params)
    magnitudes = np.linspace(0.0, 1.5, steps)
    errors = np.empty(steps)
    inputs = result.inputs
    if len(inputs) > FINE_SUBSAMPLE:
        inputs = inputs.take(even_rows(len(inputs), FINE_SUBSAMPLE))
    baseline = evaluate(inputs, Perturbation())[2]
    for k, a in enumerate(magnitudes):
        scaled = finding.fault in (Fault.DEPTH_SCALE, Fault.INTRINSICS)  # these grow from 1, not from 0
        x = 1.0 + a * (x_full - 1.0) if scaled else a * x_full
        p = evaluate(inputs, perturbation_of([model], x))[2]
        errors[k] = float(np.nanmedian(np.linalg.norm(p - baseline, axis=1)))
    label = {
        Fault.LATENCY: "pose time offset (ms)",
        Fault.MISSING_ROTATION: "rotation lost (deg)",
        Fault.ROTATION_ERROR: "rotation error (deg)",
        Fault.DEPTH_SCALE: "depth scale error (%)",
        Fault.INTRINSICS: "focal scale error (%)",
    }.get(finding.fault, "fault size (fraction of the estimate)")
    axis = magnitudes * _display_size(finding)
    return axis, errors, label


def _display_size(finding: Finding) -> float:
    e = finding.estimate
    if isinstance(e, LatencyEstimate):
        return abs(e.offset_s) * 1e3
    if isinstance(e, RotationEstimate):
        return e.angle_deg
    if isinstance(e, ScaleEstimate):
        return abs(e.value - 1.0) * 100
    return 1.0


def _params_of(finding: Finding, n: int) -> FloatArray:
    """The fitted parameter vector in the model's as-run direction, from the finding's estimate."""
    e = finding.estimate
    if isinstance(e, LatencyEstimate):
        return np.array([e.offset_s])
    if isinstance(e, RotationEstimate):
        rotvec: FloatArray = np.deg2rad(e.angle_deg) * np.asarray(e.axis, dtype=float)
        return rotvec
    if isinstance(e, ScaleEstimate):
        return np.array([e.value])
    return np.zeros(n)
