"""Verdicts an engineer can act on: a finding's size gates its fix (the chain's tolerance_m, 1 mm by default), a
verdict whose deciding fits cannot be trusted is inconclusive and never says "no fault", and a mount moved in
position is found as translation_error where the evidence can see it.

The faults come from the independent scene generator (:mod:`framechain.sim`, its own transforms and projection)
and the shared TagSLAM stairs bag; the expected values are the generator's truth and tagslam.yaml's own numbers.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from framechain import pipeline
from framechain.analysis.fit.selection import near_bound
from framechain.analysis.fit.shares import undetermined_because
from framechain.analysis.model.faults import models_for
from framechain.analysis.verdict.checks import Undetermined
from framechain.catalogue import Fault
from framechain.sim import InjectedFault, SceneSpec, generate
from framechain.timeline import PointRole
from tests.helpers.realdata import STAIRS, STAIRS_BAG
from tests.helpers.stairs import recorded_attribution, stairs_chain

MOVED_M = np.array([0.0, 0.05, 0.0])  # the mount moved 5 cm along base_link's y


# -- size gates action ----------------------------------------------------------------------------------------
def test_the_stairs_tutorial_offers_no_fix_for_an_effect_under_a_millimetre(realdata: Path) -> None:
    """The tutorial's chain on the stairs bag: the depth scale (0.2 mm of a 1.6 mm spread) and the inverted mount
    (0.0 mm) are clear fits of sub-millimetre effects: notes with their size, no fix, and the verdict says so."""
    result = recorded_attribution(realdata)
    assert result.findings
    for finding in result.findings:
        assert finding.error_m < 1e-3
        assert not finding.actionable
        assert finding.strength == "note"
        assert re.fullmatch(r"statistically clear, \d+\.\d mm: no action needed, under the 1 mm tolerance "
                            r"\(tolerance_m\)\.", finding.fix), finding.fix
        doc = finding.to_json()
        assert doc["actionable"] is False
        assert doc["effect"] == {"value": pytest.approx(finding.error_m * 1e3, abs=1e-4), "unit": "mm"}
    assert result.verdict.startswith("No fault worth acting on: median error 1.6 mm against the static spread")
    assert "no action needed" in result.verdict
    # Every bound the tolerance sets is at least what the noise alone allows, and says so.
    for bound in result.bounds:
        if bound.observable:
            assert bound.size is not None
            assert bound.statistical_size is not None
            assert bound.size >= bound.statistical_size
            assert (bound.limited_by == "tolerance") == (bound.size > bound.statistical_size)
    assert "(set by the 1 mm tolerance)" in result.verdict


def test_the_demo_s_8_mm_latency_beside_a_1_3_m_rotation_stays_a_finding() -> None:
    """The demo's failure (a mast camera whose extrinsic lost its 30 deg pitch, a pose 30 ms late, hops logged): the
    gate is absolute, so the second real fault of millimetres beside one of a metre keeps its fix."""
    faults = (InjectedFault(Fault.MISSING_ROTATION, "robot"),
              InjectedFault(Fault.LATENCY, "robot", {"offset_s": -0.03}))
    scene = generate(SceneSpec(seed=7, duration_s=8.0, evidence="hops", faults=faults))
    chain = scene.chain
    result = pipeline.run(scene.timeline, chain, bootstrap=0).attributed()
    by_fault = {f.fault: f for f in result.findings}
    rotation, latency = by_fault[Fault.MISSING_ROTATION], by_fault[Fault.LATENCY]
    assert rotation.error_m > 1.0
    assert 2e-3 < latency.error_m < 0.02  # a 30 ms late pose at the demo's speeds
    assert rotation.actionable
    assert latency.actionable
    assert latency.fix.startswith("Look up map <- base_link at the detection's header.stamp")
    assert not result.undetermined
    # With a 2 cm tolerance the latency is a note, and the pose latency bound is at least where its effect is 2 cm.
    strict = pipeline.run(scene.timeline, replace(chain, tolerance_m=0.02), bootstrap=0).attributed()
    noted = next(f for f in strict.findings if f.fault == Fault.LATENCY)
    assert noted.strength == "note"
    assert "no action needed, under the 2 cm tolerance" in noted.fix
    assert strict.verdict.startswith("missing_rotation at camera_to_body")
    assert "latency at body_to_world (-30.0 ms" in strict.verdict


# -- inconclusive ---------------------------------------------------------------------------------------------
def test_an_error_no_fault_model_explains_is_inconclusive_not_clean() -> None:
    """The robot's logged world points off by 3 cm of scatter no chain fault makes (the chain itself is right): the
    residual against exact evidence stays, so the verdict is inconclusive and never says "no fault"."""
    scene = generate(SceneSpec(seed=3, duration_s=6.0, evidence="hops"))
    points = scene.timeline.points
    world = points.role == PointRole.HOP_WORLD.value
    xyz = points.xyz.copy()
    xyz[world] += np.random.default_rng(5).normal(0.0, 0.03, (int(world.sum()), 3))
    timeline = replace(scene.timeline, points=replace(points, xyz=xyz))
    result = pipeline.run(timeline, scene.chain, bootstrap=0).attributed()
    assert result.verdict.startswith("Inconclusive: the error is undetermined (")
    assert "no fault" not in result.verdict.lower()
    assert "against the robot's logged points is left unexplained" in result.verdict
    doc = result.to_json()
    assert doc["inconclusive"] is True
    assert doc["undetermined"][0]["what"] == "the error"


def test_a_fit_at_its_window_s_edge_or_over_orders_of_magnitude_is_undetermined() -> None:
    """The wrong-robot case's numbers: a focal scale of 0.07 in 0.02 .. 102, a 146 deg mount in 86 .. 177, a time
    offset whose refits all end at the window's edge."""
    assert "spans 3.7 orders of magnitude" in undetermined_because(
        next(m for m in _models() if m.fault == Fault.INTRINSICS), np.array([0.07]), {"scale": [0.02, 102.0]}, 0.0)[0]
    rotation = next(m for m in _models() if m.fault == Fault.ROTATION_ERROR)
    assert undetermined_because(rotation, np.deg2rad([146.0, 0.0, 0.0]), {"angle_deg": [86.0, 177.0]}, 0.0) == (
        "its 95% interval 86.000 .. 177.000 deg is 91 deg wide",)
    latency = next(m for m in _models() if m.fault == Fault.LATENCY)
    assert undetermined_because(latency, np.array([0.2]), {"offset_s": [0.1, 0.3]}, 1.0) == (
        "100% of its bootstrap refits ran to the edge of its search window",)
    assert undetermined_because(latency, np.array([0.99]), {}, 0.0) == ("it lies at the edge of its search window",)
    assert undetermined_because(latency, np.array([0.03]), {"offset_s": [0.028, 0.032]}, 0.0) == ()
    # A depth factor of 9878 in 1e-4 .. 1e4 is at the edge in decades, though 1.2% from it in metres.
    depth = next(m for m in _models() if m.fault == Fault.DEPTH_SCALE)
    assert near_bound(depth, np.array([9878.0]))
    assert not near_bound(depth, np.array([1.05]))


def _models() -> list:  # type: ignore[type-arg]
    scene = generate(SceneSpec(seed=1, duration_s=2.0, evidence="hops"))
    from framechain.analysis.evidence.replayed import replay_chain
    from framechain.analysis.model.chain import ChainInputs
    from framechain.geometry.camera import CameraModel

    replayed = replay_chain(scene.timeline, scene.chain)
    camera = CameraModel.from_table(scene.timeline.cameras, replayed.replay.main_camera_row())
    return models_for(ChainInputs.from_replay(replayed.replay, replayed.buffer, camera))


def test_a_verdict_resting_on_an_undetermined_fit_is_inconclusive(realdata: Path) -> None:
    result = recorded_attribution(realdata)
    doubtful = replace(result, undetermined=(Undetermined("latency at body_to_world (+990.0 ms)",
                                                          "it lies at the edge of its search window"),))
    verdict = doubtful.verdict
    assert verdict.startswith("Inconclusive: latency at body_to_world (+990.0 ms) is undetermined (it lies at the edge "
                              "of its search window). Median error 1.6 mm against the static spread")
    assert "no fault" not in verdict.lower()
    assert "The smallest faults this log would show: " in verdict


# -- the mount's translation ------------------------------------------------------------------------------------
@pytest.mark.parametrize(("evidence", "where"), [("reference", "data"), ("hops", "robot"), ("target", "robot")])
def test_a_mount_moved_5_cm_is_a_translation_error_within_a_centimetre(evidence: str, where: str) -> None:
    moved = InjectedFault(Fault.TRANSLATION_ERROR, where, {"offset_m": MOVED_M.tolist()})  # type: ignore[arg-type]
    spec = SceneSpec(seed=3, duration_s=6.0, evidence=evidence, faults=(moved,))  # type: ignore[arg-type]
    scene = generate(spec)
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    top = result.findings[0]
    assert (top.fault, top.hop.value) == (Fault.TRANSLATION_ERROR, "camera_to_body"), result.verdict
    assert top.actionable
    estimate = top.to_json()["estimate"]
    assert estimate["frame"] == "base_link"
    # The faulty mount relative to the right one, in base_link: the generator's offset.
    assert np.linalg.norm(np.asarray(estimate["offset_m"]) - MOVED_M) < 0.01
    # The fix gives the right mount: the recorded one (the robot's was off), or the recorded one corrected.
    xyz = re.search(r'<origin xyz="([-\d.]+) ([-\d.]+) ([-\d.]+)"', top.fix)
    assert xyz is not None, top.fix
    np.testing.assert_allclose([float(v) for v in xyz.groups()], spec.mount_xyz, atol=0.01)


def test_a_fixed_camera_over_static_tags_lists_the_mount_s_translation_as_not_observable() -> None:
    scene = generate(SceneSpec(seed=4, duration_s=6.0, evidence="static", fixed_camera=True))
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    bound = next(b for b in result.bounds if b.fault == Fault.TRANSLATION_ERROR)
    assert not bound.observable
    assert "the camera does not move relative to the static targets" in bound.why
    assert "mount translation" in result.verdict.split("not observable here:")[1]


# -- per-tag sizes ----------------------------------------------------------------------------------------------
def test_stairs_tags_declared_at_the_default_size_are_named_wrongly_sized(realdata: Path) -> None:
    """Only tagslam.yaml's default 0.16 m declared: the tags it sizes at 0.10 m spread with their distance from the
    camera. They are named wrongly sized (not moving, not to be ignored), each with the size that fits."""
    chain = stairs_chain(realdata)
    chain = replace(chain, evidence=replace(chain.evidence, tag_size_m=0.16))
    result = pipeline.run(realdata / STAIRS_BAG, chain, bootstrap=0).attributed()
    bodies = yaml.safe_load((realdata / STAIRS / "tagslam.yaml").read_text())["bodies"]
    sized = {str(t["id"]): float(t["size"]) for t in bodies[0]["house"]["tags"] if float(t["size"]) != 0.16}
    rows = {r.label: r for r in result.labels.rows}
    seen = {label for label in sized if label in rows and rows[label].used >= 3}
    assert len(seen) == 8  # 100-107 (108 is not seen by this camera)
    wrong = {r.label for r in result.labels.wrongly_sized}
    assert wrong == seen
    for label in seen:
        assert rows[label].size_m == pytest.approx(sized[label], rel=0.05)
    assert not set(result.labels.suggest_ignore) & seen
    line = result.labels.size_line()
    assert line is not None
    assert line.startswith("evidence.tag_size_m: {default: 0.16, 100: 0.1")


def test_a_curve_s_axis_is_the_one_the_bounds_table_names(realdata: Path) -> None:
    """The stairs' mount rotation and translation, not found: the plot's axis is the bound's, sign included (the
    table and the plot named opposite axes); and the caption says what the median is."""
    from framechain.analysis.model.estimates import axis_text
    from framechain.sinks.checks_view import curve_plots

    result = recorded_attribution(realdata)
    for fault in (Fault.ROTATION_ERROR, Fault.TRANSLATION_ERROR):
        bound = next(b for b in result.bounds if b.fault == fault)
        curve = next(c for c in result.curves if c.fault == fault)
        assert curve.axis is not None
        assert bound.axis is not None
        np.testing.assert_allclose(curve.axis, bound.axis)
        assert axis_text(bound.axis) in bound.why
        assert axis_text(bound.axis) in curve.axis_label()
    caption = curve_plots(result)[0][1]
    assert caption.endswith("each finding's millimetres are a share of its median")
