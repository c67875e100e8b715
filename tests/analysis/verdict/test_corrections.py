"""Applying the fixes to the recorded data makes the error against the reference vanish."""

from __future__ import annotations

import numpy as np
import pytest

from framechain import pipeline
from framechain.analysis.verdict.corrections import NothingToCorrectError, apply_corrections
from framechain.catalogue import Fault
from framechain.sim.scene import InjectedFault, SceneSpec, generate


def test_three_recorded_faults_corrected_then_clean() -> None:
    faults = (InjectedFault(Fault.MISSING_ROTATION, "data"),
              InjectedFault(Fault.LATENCY, "data", {"offset_s": -0.03}),
              InjectedFault(Fault.DEPTH_SCALE, "data", {"factor": 1.05}))
    scene = generate(SceneSpec(seed=4, duration_s=6.0, evidence="reference", depth_images=True, width=320,
                               height=240, focal_px=300.0, faults=faults))
    result = pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed()
    fixed = apply_corrections(scene.timeline, result)
    again = pipeline.run(fixed, scene.chain, bootstrap=0).attributed()
    assert again.findings == ()
    # The corrected chain puts the object where the generator did, within the scene's noise.
    replayed = again.replay.p_world[again.replay.replayed]
    assert np.median(np.linalg.norm(replayed - scene.object_world, axis=1)) < 0.015
    # The stamps of everything the late camera stamped moved by the same offset.
    shift = fixed.observations.stamp_ns - scene.timeline.observations.stamp_ns
    assert np.all(np.abs(shift + 30_000_000) < 3_000_000)  # three faults fitted jointly on a 6 s episode
    np.testing.assert_array_equal(fixed.depth_frames.stamp_ns - scene.timeline.depth_frames.stamp_ns, shift)


def test_robot_side_findings_are_not_applied_to_the_log() -> None:
    scene = generate(SceneSpec(seed=4, duration_s=4.0, evidence="target",
                               faults=(InjectedFault(Fault.LATENCY, "robot", {"offset_s": -0.03}),)))
    with pytest.raises(NothingToCorrectError):
        apply_corrections(scene.timeline, pipeline.run(scene.timeline, scene.chain, bootstrap=0).attributed())
