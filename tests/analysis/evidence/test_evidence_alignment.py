"""One evidence alignment: logged points matched to observations and moved into the chain's frames.

The robot may log its points in any frame it likes (world points in odom, camera points in
camera_link, body points in base_footprint): the verdict, the findings and the picture in Rerun
must not change. The re-expressed inputs are built with scipy on the known transforms, never
with framechain's buffer.
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader
from scipy.spatial.transform import Rotation, Slerp

from framechain.analysis.evidence.alignment import PointFate, align_evidence
from framechain.analysis.model.estimates import estimate_to_json
from framechain.analysis.verdict.attribute import Attribution
from framechain.catalogue import Fault
from framechain.config.chain import ChainFrames
from framechain.pipeline import run
from framechain.replay import TransformBuffer
from framechain.sim.scene import InjectedFault, Scene, SceneSpec, generate
from framechain.sinks.rerun import RerunTarget, stream_replay
from framechain.timeline import ObservationTable, PointRole, PointTable, Timeline, TransformTable

MS = 1_000_000
#: base_link -> base_footprint: the footprint 12 cm below the base, turned 5 deg (a made-up mount).
FOOTPRINT_T = np.array([0.02, -0.01, -0.12])
FOOTPRINT_R = Rotation.from_euler("z", 5, degrees=True)


def _static(timeline: Timeline, parent: str, child: str) -> tuple[Any, Rotation]:
    tf = timeline.transforms
    row = int(np.flatnonzero((tf.parent == parent) & (tf.child == child))[0])
    return tf.translation[row], Rotation.from_quat(tf.quat_xyzw[row])


def _map_from_odom(timeline: Timeline, stamps: Any) -> tuple[Any, Rotation]:
    """T_map_odom at ``stamps``: translation linear, rotation slerp between the samples (scipy)."""
    tf = timeline.transforms
    sel = np.flatnonzero((tf.parent == "map") & (tf.child == "odom"))
    sel = sel[np.argsort(tf.stamp_ns[sel])]
    t_s = (tf.stamp_ns[sel] - tf.stamp_ns[sel][0]) / 1e9
    query = (np.asarray(stamps) - tf.stamp_ns[sel][0]) / 1e9
    translation = np.stack([np.interp(query, t_s, tf.translation[sel][:, k]) for k in range(3)], axis=1)
    return translation, Slerp(t_s, Rotation.from_quat(tf.quat_xyzw[sel]))(query)


def _in_other_frames(scene: Scene) -> Timeline:
    """The same robot points, logged in camera_link, base_footprint and odom."""
    timeline = scene.timeline
    footprint = TransformTable.from_rows("base_link", "base_footprint", [timeline.transforms.stamp_ns.min()],
                                         [FOOTPRINT_T], [FOOTPRINT_R.as_quat()], is_static=True, source="/tf_static")
    timeline = timeline.replace(transforms=TransformTable.concat([timeline.transforms, footprint]))
    points = timeline.points
    xyz = points.xyz.copy()
    frame = points.frame.astype(object).copy()
    cam = points.role == PointRole.HOP_CAMERA.value
    t_link_opt, r_link_opt = _static(timeline, "camera_link", "camera_optical_frame")
    xyz[cam] = r_link_opt.apply(xyz[cam]) + t_link_opt
    frame[cam] = "camera_link"
    body = points.role == PointRole.HOP_BODY.value
    xyz[body] = FOOTPRINT_R.inv().apply(xyz[body] - FOOTPRINT_T)  # T_fp_bl = T_bl_fp^-1
    frame[body] = "base_footprint"
    world = points.role == PointRole.HOP_WORLD.value
    t_mo, r_mo = _map_from_odom(timeline, points.stamp_ns[world])
    xyz[world] = r_mo.inv().apply(xyz[world] - t_mo)
    frame[world] = "odom"
    moved = dataclasses.replace(points, xyz=xyz, frame=np.asarray(frame, dtype=str))
    return timeline.replace(points=moved)


def _as_run_positions(rrd: Path) -> dict[str, Any]:
    batches: dict[str, list[pa.RecordBatch]] = defaultdict(list)
    for chunk in RrdReader(rrd).stream():
        if chunk.entity_path.startswith("/points/as_run/") and not chunk.is_static:
            batches[chunk.entity_path].append(chunk.to_record_batch())
    out = {}
    for entity, parts in batches.items():
        table = pa.Table.from_batches(parts)
        order = np.argsort(np.asarray(table.column("obs_index").to_pylist()))
        positions = table.column("Points3D:positions").to_pylist()
        out[entity] = np.array([positions[i][0] for i in order])
    return out


def _summary(result: Attribution) -> list[tuple[str, str, dict[str, Any], float]]:
    return [(f.fault.value, f.hop.value, estimate_to_json(f.estimate), f.share) for f in result.findings]


@pytest.mark.parametrize("faults", [(), (InjectedFault(Fault.LATENCY, params={"offset_s": -0.03}),)],
                         ids=["clean", "latency"])
def test_points_logged_in_other_frames_give_the_same_answer_and_picture(
    faults: tuple[InjectedFault, ...], tmp_path: Path
) -> None:
    scene = generate(SceneSpec(seed=5, duration_s=4.0, evidence="hops", faults=faults))
    other = _in_other_frames(scene)
    assert set(np.unique(other.points.frame)) == {"camera_link", "base_footprint", "odom"}
    logged_run, moved_run = run(scene.timeline, scene.chain, bootstrap=0), run(other, scene.chain, bootstrap=0)
    as_logged, moved = logged_run.attributed(), moved_run.attributed()
    assert moved.verdict == as_logged.verdict
    assert [(f, h) for f, h, _, _ in _summary(moved)] == [(f, h) for f, h, _, _ in _summary(as_logged)]
    for (_, _, e1, s1), (_, _, e2, s2) in zip(_summary(moved), _summary(as_logged), strict=True):
        assert e1 == pytest.approx(e2, abs=1e-6)
        assert s1 == pytest.approx(s2, abs=1e-6)
    if faults:
        assert moved.findings[0].fault == Fault.LATENCY
    else:
        assert moved.verdict.startswith("No fault beyond noise")
    # The picture: the as-run points Rerun draws are the same, and they are the robot's own (in map).
    pictures = []
    for name, made in (("logged", logged_run), ("moved", moved_run)):
        rrd = tmp_path / f"{name}.rrd"
        stream_replay(made, RerunTarget.save(rrd))
        pictures.append(_as_run_positions(rrd))
    assert set(pictures[0]) == {"/points/as_run/camera", "/points/as_run/body", "/points/as_run/world"}
    for entity, positions in pictures[0].items():
        np.testing.assert_allclose(pictures[1][entity], positions, atol=2e-6, err_msg=entity)
    replayed = as_logged.replay.replayed
    np.testing.assert_allclose(pictures[1]["/points/as_run/world"], scene.robot_world[replayed], atol=2e-6)


def test_matching_by_id_stamp_and_rank_with_counted_fates() -> None:
    """Hand-built: three detections (two in one image), points by id, by stamp, extra, far, unknown frame."""
    t0 = 1_000_000_000
    frames = ChainFrames(camera="cam", body="base_link", world="map")
    tf = TransformTable.concat([
        TransformTable.from_rows("map", "odom", [t0], [[1.0, 2.0, 0.0]], [[0.0, 0.0, 0.0, 1.0]], is_static=True),
        TransformTable.from_rows("odom", "base_link", [t0, t0 + 100 * MS], [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
                                 [[0.0, 0.0, 0.0, 1.0]] * 2),
    ])
    buffer = TransformBuffer(tf)
    stamps = np.array([t0 + 10 * MS, t0 + 50 * MS, t0 + 50 * MS])
    obs = ObservationTable(
        obs_id=np.array([7, 8, 9]), stamp_ns=stamps, log_time_ns=stamps, camera_frame=np.full(3, "cam"),
        u=np.zeros(3), v=np.zeros(3), depth_m=np.ones(3), label=np.full(3, "cup"), score=np.ones(3),
        source=np.full(3, "/det"),
    )
    rows = [  # frame, stamp, xyz, obs_id
        ("odom", t0 + 10 * MS + 200_000, [0.0, 0.0, 0.0], -1),  # obs 7 by stamp, moved from odom: (1, 2, 0)
        ("map", t0 + 50 * MS, [5.0, 0.0, 0.0], -1),  # first of the shared stamp: obs 8
        ("map", t0 + 50 * MS, [6.0, 0.0, 0.0], -1),  # second: obs 9
        ("map", t0 + 50 * MS, [7.0, 0.0, 0.0], -1),  # a third point for two detections: extra
        ("map", t0 + 80 * MS, [0.0, 0.0, 0.0], -1),  # no detection within 1 ms: no observation
        ("base_link", t0 + 30 * MS, [9.0, 9.0, 9.0], 8),  # by id (wins over stamp): base_link at 30 ms -> x + 0.3
        ("nowhere", t0 + 50 * MS, [0.0, 0.0, 0.0], 9),  # by id, but its frame is unknown: no transform
        ("map", t0, [0.0, 0.0, 0.0], 42),  # an id no detection has
    ]
    n = len(rows)
    points = PointTable(
        frame=np.array([r[0] for r in rows]), stamp_ns=np.array([r[1] for r in rows]),
        log_time_ns=np.array([r[1] for r in rows]) + np.arange(n), xyz=np.array([r[2] for r in rows], dtype=float),
        quat_xyzw=np.full((n, 4), np.nan), role=np.full(n, "hop_world"), obs_id=np.array([r[3] for r in rows]),
        source=np.full(n, "/debug/world"),
    )
    aligned = align_evidence(points, obs, frames, buffer)
    world = aligned.points(PointRole.HOP_WORLD)
    np.testing.assert_allclose(world[0], [1.0, 2.0, 0.0])
    np.testing.assert_allclose(world[1], [9.0 + 0.3 + 1.0, 11.0, 9.0])  # T_map_odom @ T_odom_base(30 ms) @ p
    assert np.isnan(world[2]).all()  # obs 9 took its own point by id, whose frame is unknown
    fates = aligned.roles[PointRole.HOP_WORLD].fates
    assert {f: n for f, n in fates.items() if n} == {
        PointFate.BY_STAMP: 1, PointFate.BY_OBS_ID: 1, PointFate.NO_TRANSFORM: 1, PointFate.EXTRA: 3,
        PointFate.NO_OBSERVATION: 2,
    }
    assert sum(fates.values()) == n
    assert any("could not be moved from nowhere into map" in note for note in aligned.notes)
    assert aligned.counts()["hop_world"]["observations_with_a_point"] == 2
