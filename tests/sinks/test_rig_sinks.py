"""A rig in every output: Rerun (a pinhole, detections and a view per camera, lines between two cameras' sightings),
the Foxglove export (annotations per camera), the CLI, attribution.json and the fleet table (the camera named)."""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import pytest
from rerun.chunk import RrdReader

from framechain import pipeline
from framechain.analysis.run import Run
from framechain.cli.main import main
from framechain.sim.rig import RigScene, RigSpec, generate_rig
from framechain.sinks.foxglove_export import ANNOTATIONS_TOPIC, foxglove_messages
from framechain.sinks.rerun import RerunOptions, RerunTarget, stream_replay
from framechain.sinks.rerun_common import entity_part
from framechain.sinks.rerun_rig import DISAGREEMENT_ENTITY
from framechain.sinks.text import FindingView

SPEC = RigSpec(cameras=3, duration_s=6.0, rate_hz=10.0, static_tags=8, turned=(1, 5.0, (1.0, 0.0, 0.0)), seed=1)


@dataclass(frozen=True)
class Made:
    scene: RigScene
    run: Run
    rrd: Path


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Made:
    scene = generate_rig(SPEC)
    run = pipeline.run(scene.timeline, scene.chain, bootstrap=0)
    rrd = tmp_path_factory.mktemp("rig") / "rig.rrd"
    stream_replay(run, RerunTarget.save(rrd), options=RerunOptions(recording_id="rig"))
    return Made(scene, run, rrd)


def _entities(rrd: Path) -> dict[str, list[Any]]:
    out: dict[str, list[Any]] = defaultdict(list)
    for chunk in RrdReader(rrd).stream():
        out[chunk.entity_path].append(chunk.to_record_batch())
    return dict(out)


def _column(batches: list[Any], suffix: str) -> list[Any]:
    return [v for b in batches for name in b.schema.names if name.endswith(suffix) for v in b.column(name).to_pylist()]


def test_every_camera_has_its_pinhole_and_detections(made: Made) -> None:
    entities = _entities(made.rrd)
    obs = made.run.replay.observations
    for camera in made.scene.chain.cameras:
        root = f"/cameras/{entity_part(camera.frame)}"
        assert _column(entities[root], "Pinhole:child_frame") == [[f"{camera.frame}_image_plane"]]
        positions = [p for rows in _column(entities[f"{root}/detections"], "Points2D:positions") for p in rows]
        mine = obs.camera_frame == camera.frame
        assert len(positions) == int(mine.sum())
        assert np.allclose(np.sort(np.asarray(positions)[:, 0]), np.sort(obs.u[mine]) + 0.5, atol=1e-3)
    assert "/camera" not in entities


def test_disagreements_are_lines_between_two_cameras_points(made: Made) -> None:
    strips = [s for rows in _column(_entities(made.rrd)[DISAGREEMENT_ENTITY], "LineStrips3D:strips") for s in rows]
    assert strips
    assert made.run.attribution is not None
    assert made.run.attribution.rig is not None
    lines = made.run.attribution.rig.lines
    assert lines is not None
    # each line starts at an observation's recomputed point and ends at another camera's point at that instant
    ends = np.asarray([s[1] for s in strips])
    assert all(np.isclose(ends, p, atol=1e-4).all(axis=1).any() for p in lines.partner_point[:20])


def test_blueprint_has_a_view_per_camera_beside_the_3d_view(made: Made) -> None:
    reader = RrdReader(made.rrd)
    targets: list[Any] = []
    classes: list[Any] = []
    for chunk in reader.stream(store=reader.blueprints()[0]):
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name.endswith("SpatialInformation:target_frame"):
                targets += batch.column(name).to_pylist()
            if name.endswith("ViewBlueprint:class_identifier"):
                classes += batch.column(name).to_pylist()
    for camera in made.scene.chain.cameras:
        assert [f"{camera.frame}_image_plane"] in targets
    assert sum(c == ["2D"] for c in classes) == len(made.scene.chain.cameras)
    assert ["3D"] in classes


def test_a_rig_shows_no_view_without_data_and_names_only_its_chain_frames(made: Made) -> None:
    from tests.helpers.rrd_views import labels_in_3d, views_without_data

    assert views_without_data(made.rrd) == []
    chain = made.scene.chain
    frames = {chain.frames.body, *(c.frame for c in chain.cameras), *([chain.frames.world] if chain.has_pose else [])}
    labels = labels_in_3d(made.rrd)
    assert labels
    assert {name for label in labels for name in label.split(" = ")} <= frames
    assert len(labels) == len(set(labels))


def test_foxglove_annotates_every_camera(made: Made) -> None:
    messages = foxglove_messages(made.run)
    topics = {m.topic for m in messages}
    for camera in made.scene.chain.cameras:
        assert f"{ANNOTATIONS_TOPIC}/{camera.frame}" in topics
    assert ANNOTATIONS_TOPIC not in topics
    transforms = [m for m in messages if m.topic == "/framechain/tf"]
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms

    children = set()
    for m in transforms[:5]:
        msg = FrameTransforms()
        msg.ParseFromString(m.data)
        children |= {t.child_frame_id for t in msg.transforms}
    assert {f"{c.frame}@replay" for c in made.scene.chain.cameras} <= children


def test_findings_name_their_camera_everywhere(made: Made, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    turned = made.scene.frame(1)
    top = made.run.findings[0]
    assert top.camera == turned
    assert f"on camera {turned}" in FindingView.of(top).headline()
    assert FindingView.of(top).cells().camera == turned
    made.scene.timeline.save(tmp_path / "tl")
    (tmp_path / "chain.yaml").write_text(made.scene.chain.to_yaml())
    assert main(["attribute", str(tmp_path / "tl"), "--chain", str(tmp_path / "chain.yaml"), "--out",
                 str(tmp_path / "out")]) == 0
    printed = capsys.readouterr().out
    assert f"fix 1 (camera {turned})" in printed
    record = json.loads((tmp_path / "out" / "attribution.json").read_text())
    assert record["findings"][0]["camera"] == turned
    assert [c["frame"] for c in record["rig"]["cameras"]] == list(made.scene.chain.camera_frames())
    assert f"| {turned} |" in (tmp_path / "out" / "report.md").read_text()
    assert main(["batch", str(tmp_path / "tl"), "--chain", str(tmp_path / "chain.yaml"), "--out",
                 str(tmp_path / "fleet"), "-j", "1"]) == 0
    table = pq.read_table(tmp_path / "fleet" / "fleet.parquet").to_pylist()
    assert table[0]["camera"] == turned
    assert f"on camera {turned}" in (tmp_path / "fleet" / "fleet_report.md").read_text()
