"""Attribution against scenes with known injected faults, at every evidence level.

The truth is what the generator injected (an independent value); assertions compare the top
finding's fault, hop and estimate with it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain import pipeline
from framechain.analysis.model.estimates import estimate_to_json
from framechain.catalogue import Fault
from framechain.sim.scene import InjectedFault, SceneSpec, generate

LEVELS_AS_RUN = ("hops", "target")
LEVELS_DATA = ("reference", "static")

# (kind, params, expected estimate key, expected value) for faults in the robot's computation.
ROBOT_FAULTS: list[tuple[Fault, dict[str, Any], str, float]] = [
    (Fault.LATENCY, {"offset_s": -0.03}, "offset_s", -0.03),
    (Fault.LATENCY, {"offset_s": 0.045}, "offset_s", 0.045),
    (Fault.MISSING_ROTATION, {}, "angle_deg", 30.0),
    (Fault.ROTATION_ERROR, {"angle_deg": 3.0, "axis": [0, 0, 1]}, "angle_deg", 3.0),
    (Fault.DEPTH_SCALE, {"factor": 1.05}, "factor", 1.05),
    (Fault.INTRINSICS, {"scale": 2.0}, "scale", 2.0),
    (Fault.AXIS_FLIP, {"permutation": [[1, 0, 0], [0, -1, 0], [0, 0, 1]]}, "", 0.0),
    (Fault.WRONG_WORLD_FRAME, {}, "", 0.0),
    (Fault.INVERTED_TRANSFORM, {"hop": "camera_to_body"}, "", 0.0),
    (Fault.INVERTED_TRANSFORM, {"hop": "body_to_world"}, "", 0.0),
]
# Faults in the recorded data: found against a reference or by the static target's spread.
DATA_FAULTS: list[tuple[Fault, dict[str, Any], str, float]] = [
    (Fault.LATENCY, {"offset_s": -0.03}, "offset_s", -0.03),
    (Fault.MISSING_ROTATION, {}, "angle_deg", 30.0),
    (Fault.ROTATION_ERROR, {"angle_deg": 3.0, "axis": [0, 0, 1]}, "angle_deg", 3.0),
    (Fault.DEPTH_SCALE, {"factor": 1.05}, "factor", 1.05),
    (Fault.INTRINSICS, {"scale": 2.0}, "scale", 2.0),
]
TOLERANCE = {"offset_s": 0.002, "angle_deg": 0.5, "factor": 0.01, "scale": 0.01}


def _scene(evidence: str, faults: tuple[InjectedFault, ...], seed: int = 3) -> Any:
    return generate(SceneSpec(seed=seed, duration_s=6.0, evidence=evidence, faults=faults))  # type: ignore[arg-type]


def _check_top(result: Any, fault: InjectedFault, key: str, value: float) -> None:
    assert result.findings, f"nothing found for {fault}"
    top = result.findings[0]
    assert (top.fault.value, top.hop.value) == (fault.kind.value, fault.hop), [
        (f.fault.value, f.hop.value, f.estimate) for f in result.findings]
    if key:
        rel = key in ("factor", "scale")
        error = abs(estimate_to_json(top.estimate)[key] - value) / (abs(value) if rel else 1.0)
        assert error <= TOLERANCE[key], (top.estimate, value)


@pytest.mark.parametrize("level", LEVELS_AS_RUN)
@pytest.mark.parametrize(("kind", "params", "key", "value"), ROBOT_FAULTS,
                         ids=[f"{k.value}-{i}" for i, (k, *_rest) in enumerate(ROBOT_FAULTS)])
def test_robot_fault_found_from_logged_points(level: str, kind: Fault, params: dict[str, Any], key: str,
                                              value: float) -> None:
    fault = InjectedFault(kind, "robot", params)
    scene = _scene(level, (fault,))
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    _check_top(result, fault, key, value)
    assert result.metric == ("logged_hops" if level == "hops" else "target")


@pytest.mark.parametrize("level", LEVELS_DATA)
@pytest.mark.parametrize(("kind", "params", "key", "value"), DATA_FAULTS,
                         ids=[f"{k.value}-{i}" for i, (k, *_rest) in enumerate(DATA_FAULTS)])
def test_data_fault_found_against_reference_or_spread(level: str, kind: Fault, params: dict[str, Any],
                                                      key: str, value: float) -> None:
    fault = InjectedFault(kind, "data", params)
    scene = _scene(level, (fault,))
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    _check_top(result, fault, key, value)


@pytest.mark.parametrize("level", LEVELS_DATA)
def test_recorded_axis_flip_and_inverted_mount(level: str) -> None:
    flip = InjectedFault(Fault.AXIS_FLIP, "data", {"permutation": [[-1, 0, 0], [0, -1, 0], [0, 0, 1]]})
    scene = _scene(level, (flip,))
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    assert (result.findings[0].fault, estimate_to_json(result.findings[0].estimate)["permutation"]) == (
        Fault.AXIS_FLIP, [[-1, 0, 0], [0, -1, 0], [0, 0, 1]])
    inverted = InjectedFault(Fault.INVERTED_TRANSFORM, "data", {"hop": "camera_to_body"})
    scene = _scene(level, (inverted,))
    top = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed().findings[0]
    assert top.fault == Fault.INVERTED_TRANSFORM
    assert estimate_to_json(top.estimate)["edge"] == ["base_link", "camera_link"]


@pytest.mark.parametrize("level", ["hops", "target", "reference", "static"])
def test_clean_log_has_no_finding(level: str) -> None:
    for seed in (1, 2):
        scene = _scene(level, (), seed=seed)
        result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
        assert [f for f in result.findings if f.share > 0.1] == []
        assert result.verdict.startswith("No fault beyond noise")


@pytest.mark.parametrize("level", ["hops", "target", "reference"])
def test_combined_missing_rotation_and_latency(level: str) -> None:
    where = "data" if level == "reference" else "robot"
    faults = (InjectedFault(Fault.MISSING_ROTATION, where),
              InjectedFault(Fault.LATENCY, where, {"offset_s": -0.03}))
    scene = _scene(level, faults)
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    by_fault = {f.fault: f for f in result.findings}
    assert set(by_fault) == {Fault.MISSING_ROTATION, Fault.LATENCY}
    assert abs(estimate_to_json(by_fault[Fault.MISSING_ROTATION].estimate)["angle_deg"] - 30.0) < 0.5
    assert abs(estimate_to_json(by_fault[Fault.LATENCY].estimate)["offset_s"] + 0.03) < 0.002
    # Shares add up to the explained error and are sorted largest first.
    shares = [f.share for f in result.findings]
    assert shares == sorted(shares, reverse=True)
    assert 0.9 < sum(shares) <= 1.0 + 1e-6


def test_latency_and_depth_scale_in_one_pass_from_target() -> None:
    faults = (InjectedFault(Fault.DEPTH_SCALE, "robot", {"factor": 0.9}),
              InjectedFault(Fault.LATENCY, "robot", {"offset_s": 0.02}))
    scene = _scene("target", faults)
    findings = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed().findings
    found = {f.fault: estimate_to_json(f.estimate) for f in findings}
    assert abs(found[Fault.DEPTH_SCALE]["factor"] - 0.9) < 0.009
    assert abs(found[Fault.LATENCY]["offset_s"] - 0.02) < 0.002


def test_missing_rotation_fix_names_the_corrected_mount() -> None:
    scene = _scene("hops", (InjectedFault(Fault.MISSING_ROTATION, "robot"),))
    top = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed().findings[0]
    # The mount is pitched 30 deg about y: rpy = (0, 0.5236, 0) rad, independent of the code under test.
    rpy = Rotation.from_euler("y", 30, degrees=True).as_euler("xyz")
    assert f'rpy="{rpy[0]:.5f} {rpy[1]:.5f} {rpy[2]:.5f}"' in top.fix
    assert "--frame-id base_link --child-frame-id camera_link" in top.fix
    assert estimate_to_json(top.estimate)["axis"] == pytest.approx([0.0, -1.0, 0.0], abs=1e-3)


def test_bootstrap_interval_covers_the_injected_latency() -> None:
    fault = InjectedFault(Fault.LATENCY, "data", {"offset_s": -0.03})
    scene = _scene("reference", (fault,))
    top = pipeline.run(scene.timeline, scene.chain, bootstrap=20, seed=5).attributed().findings[0]
    lo, hi = top.interval["offset_s"]
    assert lo <= -0.03 <= hi
    assert hi - lo < 0.01


def test_attribution_json_contract() -> None:
    scene = _scene("hops", (InjectedFault(Fault.LATENCY, "robot", {"offset_s": -0.03}),))
    doc = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed().to_json()
    assert doc["schema"] == "framechain/attribution@1"
    assert set(doc["frames"]) == {"camera", "body", "world"}
    obs = doc["observations"]
    assert obs["replayed"] + sum(obs["rejected"].values()) == obs["total"]
    assert doc["error_m"]["metric"] == "logged_hops"
    finding = doc["findings"][0]
    assert set(finding) >= {"fault", "hop", "estimate", "share", "error_m", "confidence", "evidence", "fix"}
    assert finding["fault"] in {f.value for f in Fault}
    assert finding["hop"] in {"pixel_to_camera", "camera_to_body", "body_to_world"}
    # The world error is the distance from what the robot acted on to the object the generator placed
    # (the truth); the recomputed point differs from the truth only by pixel and depth noise (mm).
    truth = np.linalg.norm(scene.robot_world - scene.object_world, axis=1)
    assert doc["error_m"]["median"] == pytest.approx(float(np.median(truth)), abs=3e-3)
    assert doc["error_m"]["median"] > 0.01  # a 30 ms latency at up to 1 m/s is centimetres


def test_hop_summary_gaps_and_attribution() -> None:
    scene = _scene("reference", (InjectedFault(Fault.LATENCY, "data", {"offset_s": -0.03}),))
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    rows = {r["hop"]: r for r in result.to_json()["hops"]}
    assert list(rows) == ["pixel_to_camera", "camera_to_body", "body_to_world"]
    # Independent: per observation, the largest distance to the nearest sample over the dynamic edges
    # between map and base_link (each edge's stamps taken straight from the recorded transforms).
    tf = scene.timeline.transforms
    stamps = scene.timeline.observations.stamp_ns[result.replay.replayed]
    worst = np.zeros(stamps.size)
    for child in ("odom", "base_link"):
        edge = np.sort(tf.stamp_ns[(tf.child == child) & ~tf.is_static])
        i = np.clip(np.searchsorted(edge, stamps), 1, edge.size - 1)
        worst = np.maximum(worst, np.minimum(np.abs(stamps - edge[i - 1]), np.abs(edge[i] - stamps)))
    assert rows["body_to_world"]["gap_ms"]["median"] == pytest.approx(np.median(worst) * 1e-6, abs=1e-3)
    assert rows["body_to_world"]["gap_ms"]["max"] == pytest.approx(worst.max() * 1e-6, abs=1e-3)
    assert rows["camera_to_body"]["gap_ms"] == {"median": 0.0, "max": 0.0}  # static mount
    # The finding's error is put on its hop, nothing on the others; no hop points were logged.
    top = result.findings[0]
    assert rows["body_to_world"]["faults"] == ["latency"]
    assert rows["body_to_world"]["attributed_m"] == pytest.approx(top.error_m, abs=1e-6)
    assert rows["camera_to_body"]["attributed_m"] == 0.0
    assert all(r["departure_m"] is None for r in rows.values())
