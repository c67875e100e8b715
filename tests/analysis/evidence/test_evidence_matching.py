"""Evidence that is partial, misaligned or shared by several detections of one image."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from framechain import pipeline
from framechain.catalogue import Fault
from framechain.replay import replay
from framechain.sim.scene import InjectedFault, SceneSpec, generate
from framechain.timeline import ObservationTable, PointRole, PointTable

MISSING = InjectedFault(Fault.MISSING_ROTATION)
LATENCY = InjectedFault(Fault.LATENCY, params={"offset_s": -0.03})


def _keep(scene: object, roles: list[PointRole]) -> object:
    points = scene.timeline.points  # type: ignore[attr-defined]
    return scene.timeline.replace(points=points.take(np.isin(points.role, [r.value for r in roles])))  # type: ignore[attr-defined]


@pytest.mark.parametrize(("fault", "roles", "stage"), [
    (MISSING, [PointRole.HOP_CAMERA, PointRole.HOP_BODY], "body"),
    (MISSING, [PointRole.HOP_WORLD], "world"),
    (LATENCY, [PointRole.HOP_CAMERA, PointRole.HOP_WORLD], "world"),
])
def test_partially_logged_hops(fault: InjectedFault, roles: list[PointRole], stage: str) -> None:
    scene = generate(SceneSpec(seed=3, duration_s=6.0, evidence="hops", faults=(fault,)))
    result = pipeline.run(_keep(scene, roles), scene.chain, bootstrap=0).attributed()  # type: ignore[arg-type]
    top = result.findings[0]
    assert (top.fault.value, top.hop.value) == (fault.kind.value, fault.hop)
    assert top.share > 0.95
    summary = result.error_summary()
    assert summary["stage"] == stage
    # Independent size of the error: the robot's own points against the same scene run clean.
    clean = generate(SceneSpec(seed=3, duration_s=6.0, evidence="hops"))
    if stage == "world":
        expected = np.median(np.linalg.norm(scene.robot_world - clean.robot_world, axis=1))
        assert summary["median"] == pytest.approx(expected, abs=1e-6)
    else:
        assert summary["median"] > 0.5  # a 30 deg rotation at about 2.5 m


def test_points_stamped_off_the_detection_are_named_in_the_notes() -> None:
    scene = generate(SceneSpec(seed=3, duration_s=6.0, evidence="hops", faults=(MISSING,)))
    points = scene.timeline.points
    shifted = dataclasses.replace(points, stamp_ns=points.stamp_ns + 5_000_000)  # stamped with now(), 5 ms late
    result = pipeline.run(scene.timeline.replace(points=shifted), scene.chain, bootstrap=0).attributed()
    assert any("/debug/point_world" in n and "5.0 ms" in n for n in result.notes)
    assert result.metric == "static_spread"  # the fallback is said, not silent


def test_two_detections_per_image_match_their_own_points() -> None:
    scene = generate(SceneSpec(seed=3, duration_s=6.0, evidence="hops"))
    timeline = scene.timeline
    obs = timeline.observations
    n = len(obs)
    second = dataclasses.replace(obs, obs_id=obs.obs_id + n, u=obs.u + 15.0, v=obs.v + 10.0, depth_m=obs.depth_m * 1.1)
    both = timeline.replace(observations=ObservationTable.concat([obs, second]))
    clean = replay(both, scene.chain.frames)  # the robot is right: its points are the clean chain's
    extra = []
    for role, values in ((PointRole.HOP_CAMERA, clean.p_cam), (PointRole.HOP_BODY, clean.p_body),
                         (PointRole.HOP_WORLD, clean.p_world)):
        base = timeline.points.with_role(role)
        extra.append(dataclasses.replace(base, xyz=values[n:]))
    both = both.replace(points=PointTable.concat([timeline.points, *extra]))
    result = pipeline.run(both, scene.chain, bootstrap=0).attributed()
    assert result.findings == ()
    assert result.error_summary()["median"] < 1e-9
    assert any("share a stamp" in note for note in result.notes)
