"""What a verdict can be checked against: weak findings worded as hints, the error against each family's size (the
same median error the findings' millimetres are shares of), the per-label table with the labels to ignore, and the
attribution.json additions."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from framechain import pipeline
from framechain.analysis.fit.shares import WEAK_CONFIDENCE, weakened
from framechain.analysis.model.estimates import LatencyEstimate, RotationEstimate, ScaleEstimate
from framechain.analysis.verdict.checks import Bound, bounds_sentence
from framechain.analysis.verdict.curves import label_table
from framechain.analysis.verdict.findings import Finding
from framechain.catalogue import Fault, HopName
from framechain.pipeline import load_log
from framechain.sim import InjectedFault, SceneSpec, generate
from tests.helpers.realdata import STAIRS_BAG
from tests.helpers.stairs import stairs_chain


def _finding(fault: Fault, hop: HopName, estimate: Any, interval: dict[str, list[float]], confidence: float) -> Finding:
    return Finding(fault=fault, hop=hop, estimate=estimate, interval=interval, share=0.2, error_m=0.001,
                   confidence=confidence, evidence="", fix="Recalibrate the camera.", model="m")


def test_weak_findings_are_hints_and_strong_ones_stay() -> None:
    bound = Bound(HopName.PIXEL_TO_CAMERA, Fault.INTRINSICS, True, {"scale": 0.01}, "")
    rotation_bound = Bound(HopName.CAMERA_TO_BODY, Fault.ROTATION_ERROR, True, {"angle_deg": 0.5}, "")
    # The lab log's: x0.9748 with an interval x0.958..x1.008 (it holds x1), at confidence 1.00.
    holds_one = _finding(Fault.INTRINSICS, HopName.PIXEL_TO_CAMERA, ScaleEstimate("scale", 0.9748, "focal"),
                         {"scale": [0.958, 1.008]}, 1.0)
    # The yard log's: x0.9474 at confidence 0.04.
    unsure = _finding(Fault.INTRINSICS, HopName.PIXEL_TO_CAMERA, ScaleEstimate("scale", 0.9474, "focal"),
                      {"scale": [0.93, 0.96]}, 0.04)
    small = _finding(Fault.ROTATION_ERROR, HopName.CAMERA_TO_BODY, RotationEstimate(0.3, (0.0, 1.0, 0.0), "cam", "x"),
                     {"angle_deg": [0.2, 0.4]}, 0.99)
    zero_offset = _finding(Fault.LATENCY, HopName.BODY_TO_WORLD, LatencyEstimate(0.004),
                           {"offset_s": [-0.001, 0.009]}, 0.9)
    clear = _finding(Fault.LATENCY, HopName.BODY_TO_WORLD, LatencyEstimate(0.030), {"offset_s": [0.028, 0.032]}, 0.99)
    out = weakened([holds_one, unsure, small, zero_offset, clear], [bound, rotation_bound])
    assert [f.strength for f in out] == ["weak", "weak", "weak", "weak", "strong"]
    assert out[0].weak_because == ("its 95% interval x0.958 .. x1.008 holds no fault",)
    assert out[1].weak_because == (f"confidence 0.04 under {WEAK_CONFIDENCE:g}",)
    assert out[2].weak_because == ("under the 0.5 deg this log shows reliably",)
    assert "holds no fault" in out[3].weak_because[0]
    for weak in out[:4]:
        assert weak.fix.startswith("weak (")
        assert "before changing anything; if it holds up: recalibrate the camera." in weak.fix
        assert weak.to_json()["strength"] == "weak"
    assert out[4] == clear
    assert out[4].to_json()["strength"] == "strong"
    assert out[4].to_json()["weak_because"] == []


def test_the_bounds_sentence_leaves_out_the_families_found() -> None:
    bounds = [Bound(HopName.BODY_TO_WORLD, Fault.LATENCY, True, {"offset_s": 0.004}, ""),
              Bound(HopName.CAMERA_TO_BODY, Fault.ROTATION_ERROR, True, {"angle_deg": 0.3}, ""),
              Bound(HopName.PIXEL_TO_CAMERA, Fault.DEPTH_SCALE, True, {"factor": 0.01}, ""),
              Bound(HopName.PIXEL_TO_CAMERA, Fault.INTRINSICS, False, None, "bearing only")]
    assert bounds_sentence(bounds) == ("No fault above 4 ms pose latency, 0.3 deg mount rotation and 1% depth scale "
                                       "(set by the noise); not observable here: intrinsics scale (bearing only).")
    assert bounds_sentence(bounds, [(Fault.MISSING_ROTATION, HopName.CAMERA_TO_BODY, None)]) == (
        "No other fault above 4 ms pose latency and 1% depth scale (set by the noise); not observable here: "
        "intrinsics scale (bearing only).")


def test_the_bounds_sentence_names_each_camera_once_and_leaves_out_only_that_camera_s_findings() -> None:
    latency = Fault.LATENCY, HopName.CAMERA_TO_BODY
    bounds = [Bound(HopName.CAMERA_TO_BODY, Fault.LATENCY, True, {"offset_s": 0.007}, "", camera="wrist"),
              Bound(HopName.CAMERA_TO_BODY, Fault.ROTATION_ERROR, True, {"angle_deg": 1.2}, "", camera="wrist"),
              Bound(HopName.CAMERA_TO_BODY, Fault.LATENCY, False, None, "front is fixed in world", camera="front"),
              Bound(HopName.CAMERA_TO_BODY, Fault.ROTATION_ERROR, False, None, "front is fixed in world",
                    camera="front")]
    assert bounds_sentence(bounds) == (
        "No fault above 7 ms camera latency and 1.2 deg mount rotation (set by the noise) on camera wrist; not "
        "observable here: camera "
        "latency and mount rotation on camera front (front is fixed in world).")
    # A latency found on the wrist camera leaves out the wrist's latency bound only.
    assert bounds_sentence(bounds, [(*latency, "wrist")]).startswith(
        "No other fault above 1.2 deg mount rotation (set by the noise) on camera wrist; not observable here: camera "
        "latency and")
    assert bounds[0].to_json()["camera"] == "wrist"


def test_a_rig_s_bounds_are_said_per_camera() -> None:
    """A rig camera's bounds name it once after its families; a finding on one camera leaves that camera's family out
    only; a gauge camera's families not observable are named with their cause."""
    def on(camera: str, fault: Fault, hop: HopName, size: dict[str, float] | None, why: str = "") -> Bound:
        return Bound(hop, fault, size is not None, size, why, camera=camera)

    gauge = "cam0 sets the gauge of its pair with cam1: its fault shows on camera cam1"
    bounds = [on("cam1", Fault.LATENCY, HopName.BODY_TO_WORLD, {"offset_s": 0.025}),
              on("cam1", Fault.ROTATION_ERROR, HopName.CAMERA_TO_BODY, {"angle_deg": 2.0}),
              on("cam2", Fault.ROTATION_ERROR, HopName.CAMERA_TO_BODY, {"angle_deg": 9.5}),
              on("cam0", Fault.LATENCY, HopName.BODY_TO_WORLD, None, gauge),
              on("cam0", Fault.ROTATION_ERROR, HopName.CAMERA_TO_BODY, None, gauge)]
    assert bounds_sentence(bounds) == (
        "No fault above 25 ms latency and 2 deg mount rotation (set by the noise) on camera cam1; 9.5 deg mount "
        "rotation (set by the noise) on camera cam2; not observable here: latency and mount rotation on camera cam0 "
        "(cam0 sets the gauge of its pair with cam1).")
    assert bounds_sentence(bounds, [(Fault.ROTATION_ERROR, HopName.CAMERA_TO_BODY, "cam2")]).startswith(
        "No other fault above 25 ms latency and 2 deg mount rotation (set by the noise) on camera cam1; not "
        "observable here")
    assert bounds[0].to_json()["camera"] == "cam1"
    assert "camera" not in Bound(HopName.BODY_TO_WORLD, Fault.LATENCY, True, {"offset_s": 0.004}, "").to_json()


def test_the_latency_curve_dips_at_the_truth_and_measures_what_the_finding_shares() -> None:
    """A 30 ms stamp offset in the data of a static-target scene: the curve's dip is the generator's
    offset, and the curve at no offset less the curve at the estimate is the finding's millimetres."""
    latency = InjectedFault(Fault.LATENCY, "data", {"offset_s": 0.030})
    scene = generate(SceneSpec(seed=6, duration_s=6.0, evidence="static", faults=(latency,)))
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    (finding,) = result.findings
    assert finding.fault == Fault.LATENCY
    curve = next(c for c in result.curves if c.fault == Fault.LATENCY)
    x, y, rms = np.array(curve.x), np.array(curve.median_error_m), np.array(curve.rms_error_m)
    # The fit minimises the sum of squares (reweighted along the rays): the rms dip is at the estimate.
    assert x[np.nanargmin(rms)] == pytest.approx(curve.estimate, abs=0.001)
    assert curve.estimate == pytest.approx(0.030, abs=0.002)
    assert x.min() == pytest.approx(-1.0)
    assert x.max() == pytest.approx(1.0)
    at_zero, at_estimate = y[np.argmin(np.abs(x))], y[np.argmin(np.abs(x - curve.estimate))]
    assert at_zero == pytest.approx(float(np.nanmedian(result.error_before)), rel=1e-9)
    assert at_zero - at_estimate == pytest.approx(finding.error_m, rel=1e-6)
    doc = result.to_json()
    assert {c["fault"] for c in doc["curves"]} == {"latency", "rotation_error", "translation_error", "depth_scale",
                                                   "intrinsics"}
    latency_json = next(c for c in doc["curves"] if c["fault"] == "latency")
    assert latency_json["key"] == "offset_s"
    assert len(latency_json["x"]) == len(latency_json["median_error_m"])


def test_a_long_log_s_curves_are_measured_on_evenly_spread_observations(monkeypatch: pytest.MonkeyPatch) -> None:
    """Past CURVE_ROWS observations a curve is measured on that many, evenly spread (as the fit's fine
    grid is): its dip stays at the estimate, and its value at no offset stays the median error the
    findings share out, to the spread a median of fewer observations has."""
    from framechain.analysis.fit.least_squares import subsample
    from framechain.analysis.verdict import curves

    latency = InjectedFault(Fault.LATENCY, "data", {"offset_s": 0.030})
    scene = generate(SceneSpec(seed=6, duration_s=6.0, evidence="static", faults=(latency,)))
    monkeypatch.setattr(curves, "CURVE_ROWS", 50)
    measured: list[tuple[int, int]] = []  # (rows given, rows the curve is measured on)

    def spy(objective: Any, inputs: Any, size: int) -> Any:
        out = subsample(objective, inputs, size)
        measured.append((len(inputs), len(out[1])))
        return out

    monkeypatch.setattr(curves, "subsample", spy)
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    assert len(result.inputs) > 3 * 50  # the curve is measured on a third of the observations or fewer
    [(given, rows)] = measured  # one stage's curves, measured on 50 of its observations
    assert rows == 50 < given
    curve = next(c for c in result.curves if c.fault == Fault.LATENCY)
    x, y, rms = np.array(curve.x), np.array(curve.median_error_m), np.array(curve.rms_error_m)
    assert curve.estimate == pytest.approx(0.030, abs=0.002)
    assert x[np.nanargmin(rms)] == pytest.approx(curve.estimate, abs=0.002)
    at_zero = y[np.argmin(np.abs(x))]
    assert at_zero == pytest.approx(float(np.nanmedian(result.error_before)), rel=0.25)


def test_label_table_verdicts() -> None:
    rng = np.random.default_rng(3)
    labels = np.repeat(np.array(["1", "2", "3", "tag_a", "5"]), 40)
    errors = np.abs(rng.normal(0.0, 0.002, labels.size))
    errors[labels == "3"] += 0.02  # moves as a whole
    errors[np.flatnonzero(labels == "tag_a")[:12]] = 0.05  # a few sightings far off
    errors[labels == "5"] = np.nan  # never used
    table = label_table(labels, errors, static=True)
    assert [(r.label, r.verdict) for r in table.rows] == [
        ("1", "static"), ("2", "static"), ("3", "moving"), ("5", "too few"), ("tag_a", "outlier")]
    assert table.ignore_line() == "evidence.ignore_labels: [3, 'tag_a']"
    assert table.rows[0].observations == 40
    assert table.rows[3].used == 0
    other = label_table(labels, errors, static=False)
    assert [r.verdict for r in other.rows] == ["agrees", "agrees", "outlier", "too few", "outlier"]


def test_a_moving_tag_on_the_stairs_is_named_and_ignoring_it_clears_the_table(realdata: Any) -> None:
    """Tag 22 made to move (its depths swing by 5 % every 3 s, about 10 cm): the table names it alone, and
    the ready line, put in the chain, leaves it out."""
    chain = stairs_chain(realdata)
    timeline = load_log(realdata / STAIRS_BAG, chain).timeline
    obs = timeline.observations
    swing = 1.0 + 0.05 * np.sin(2 * np.pi * (obs.stamp_ns - obs.stamp_ns.min()) * 1e-9 / 3.0)
    moved = timeline.replace(observations=replace(obs, depth_m=np.where(obs.label == "22", obs.depth_m * swing,
                                                                        obs.depth_m)))
    table = pipeline.run(moved, chain, bootstrap=0).attributed().labels
    assert table.suggest_ignore == ("22",)
    assert table.ignore_line() == "evidence.ignore_labels: [22]"
    assert next(r for r in table.rows if r.label == "22").spread_m > 5 * (table.overall_m or 0.0)
    ignoring = replace(chain, evidence=replace(chain.evidence, ignore_labels=("22",)))
    again = pipeline.run(moved, ignoring, bootstrap=0).attributed().labels
    assert "22" not in {r.label for r in again.rows}
    assert again.suggest_ignore == ()
