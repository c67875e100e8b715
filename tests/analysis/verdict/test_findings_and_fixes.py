"""Findings explain a share of the error, and fixes blame where the inputs came from.

A fault whose Shapley share of the median error is not positive is no finding (a note names it);
a fix names the calibration file or CameraInfo topic the intrinsics came from, and a depth scale
on depths from tag corners names both causes (tag size, odometry scale).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from framechain import pipeline
from framechain.analysis.model.estimates import ScaleEstimate
from framechain.analysis.verdict.fixes import FixContext, fix_for
from framechain.catalogue import Fault, HopName
from framechain.config.chain import ChainConfig
from framechain.sim.scene import TOPICS, InjectedFault, SceneSpec, generate
from tests.helpers.realdata import ARUCO_IMAGES_BAG, aruco_images_chain


def _reference_run(fault: InjectedFault, *, depth_images: bool = False) -> object:
    spec = SceneSpec(seed=3, duration_s=4.0, evidence="reference", faults=(fault,), depth_images=depth_images)
    scene = generate(spec)
    return pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()


def test_intrinsics_fix_names_the_recorded_camera_info_topic() -> None:
    result = _reference_run(InjectedFault(Fault.INTRINSICS, "data", {"scale": 2.0}))
    top = result.findings[0]  # type: ignore[attr-defined]
    assert top.fault == Fault.INTRINSICS
    assert f"The recorded CameraInfo on {TOPICS.camera_info} has the K" in top.fix
    assert "file" not in top.fix


def test_intrinsics_fix_from_a_calibration_file_blames_the_file() -> None:
    result = _reference_run(InjectedFault(Fault.INTRINSICS, "data", {"scale": 2.0}))
    inputs = result.inputs  # type: ignore[attr-defined]
    estimate = ScaleEstimate("scale", 2.0, "resolution")
    text = fix_for(Fault.INTRINSICS, HopName.PIXEL_TO_CAMERA, estimate, inputs, np.array([2.0]), "correction",
                   context=FixContext(camera_source="cameras.yaml [cam2]", camera_from_file=True))
    assert text.startswith("The intrinsics from cameras.yaml [cam2] are those of another resolution"), text
    assert "CameraInfo" not in text
    # The K that fits: the recorded focal length and principal point halved (K of another resolution).
    assert f"fx {inputs.camera.fx / 2:.1f}" in text
    assert f"cx {inputs.camera.cx / 2:.1f}" in text
    assert text.count(". ") == 0  # one sentence
    assert text.endswith(".")


@pytest.mark.parametrize(("context", "wanted", "unwanted"), [
    (FixContext(depth_from_images=True), ["16UC1", "depth images"], ["tag size", "odometry"]),
    (FixContext(depth_from_tag_size=True), ["tag size", "odometry/VIO", "markers.size_m"], ["16UC1"]),
    (FixContext(), ["detector's depth", "odometry/VIO"], ["16UC1", "tag size"]),
])
def test_depth_scale_fix_names_the_causes_of_its_depth_source(
    context: FixContext, wanted: list[str], unwanted: list[str]
) -> None:
    result = _reference_run(InjectedFault(Fault.DEPTH_SCALE, "data", {"factor": 1.05}))
    inputs = result.inputs  # type: ignore[attr-defined]
    factor = 1000.0 if context.depth_from_images else 1.017
    text = fix_for(Fault.DEPTH_SCALE, HopName.PIXEL_TO_CAMERA, ScaleEstimate("factor", factor), inputs,
                   np.array([factor]), "correction", context=context)
    assert f"Scale depth by {1 / factor:.6g}" in text
    assert all(w in text for w in wanted), text
    assert not any(u in text for u in unwanted), text
    if context.depth_from_tag_size:
        assert f"declare sizes {1 / factor:.4g} times" in text


def test_attribute_knows_depth_came_from_depth_images() -> None:
    result = _reference_run(InjectedFault(Fault.DEPTH_SCALE, "data", {"factor": 1.05}), depth_images=True)
    top = result.findings[0]  # type: ignore[attr-defined]
    assert top.fault == Fault.DEPTH_SCALE
    assert "depth images" in top.fix
    assert "tag size" not in top.fix


def test_findings_that_explain_nothing_are_notes_on_a_real_log(realdata: Path) -> None:
    """ArUco markers against a declared reference point: a depth scale fitted there makes the median error worse
    (-32 mm of it), so it is a note, not a finding at conf 1.00."""
    bag = realdata / ARUCO_IMAGES_BAG
    if not bag.is_file():
        pytest.skip(f"{bag} not present")
    chain = ChainConfig.from_dict(aruco_images_chain(
        {"markers": {"dictionary": "DICT_5X5_1000", "size_m": 0.14}, "reference_point": [1.0, 0.0, 0.3]}))
    result = pipeline.run(bag, chain, bootstrap=0).attributed()
    assert all(f.share > 0 and f.error_m > 0 for f in result.findings), [(f.model, f.share) for f in result.findings]
    dropped = [n for n in result.notes if "is no finding" in n]
    assert any(n.startswith("depth_scale x") for n in dropped), result.notes
    # With nothing left the residual is the error itself: 442 mm against a point declared for seven markers at
    # different places is no noise a reference has, so the verdict is inconclusive, never "no fault".
    if not result.findings:
        np.testing.assert_allclose(result.error_after, result.error_before)
        assert result.verdict.startswith("Inconclusive: the error is undetermined (")
        assert "no fault" not in result.verdict.lower()
        assert result.to_json()["inconclusive"] is True
