"""The CLI on a LeRobot dataset: framechain replay|attribute|report DATASET --episode N --robot robot.yaml."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from framechain.adapters.errors import AdapterError
from framechain.adapters.lerobot.adapter import LeRobotAdapter, scan_dataset
from framechain.cli.main import main
from framechain.config.chain import ChainConfig
from tests.helpers.lerobot_scene import (
    FPS,
    ArmDataset,
    target_world,
    write_arm_dataset,
    write_detection_table,
    write_robot_yaml,
)

DELAY_S = 0.04


@pytest.fixture(scope="module")
def latency_case(tmp_path_factory: pytest.TempPathFactory) -> tuple[ArmDataset, Path]:
    """A 3 s episode whose wrist camera lags 40 ms behind the joint states, with nothing recording it."""
    folder = tmp_path_factory.mktemp("cli")
    ds = write_arm_dataset(folder / "ds", version="v3.0", lengths=(90, 30), camera_delay_s=DELAY_S)
    write_detection_table(folder / "det.parquet", ds, 0, frames=np.arange(14, 77, 2))
    robot = write_robot_yaml(folder, detections=[{"table": "det.parquet"}], chain={
        "camera": "wrist", "latency_budget_s": 0.02,
        "evidence": {"reference_point": [float(x) for x in target_world()], "static_target": True},
    })
    return ds, robot


def test_attribute_finds_the_camera_latency(latency_case: tuple[ArmDataset, Path], tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    ds, robot = latency_case
    code = main(["attribute", str(ds.root), "--episode", "0", "--robot", str(robot), "--out", str(tmp_path),
                 "--bootstrap", "5", "--json", "-q"])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    top = result["findings"][0]
    assert (top["fault"], top["hop"]) == ("latency", "camera_to_body")
    assert top["estimate"]["offset_s"] == pytest.approx(DELAY_S, abs=2e-3)
    assert (tmp_path / "attribution.json").is_file()


def test_replay_saves_a_recording(latency_case: tuple[ArmDataset, Path], tmp_path: Path,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    from rerun.chunk import RrdReader

    ds, robot = latency_case
    rrd = tmp_path / "episode0.rrd"
    assert main(["replay", str(ds.root), "--episode", "0", "--robot", str(robot), "--save", str(rrd), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["counts"] == {"total": 32, "replayed": 32, "rejected": {}, "stale": 0}  # 32 detections
    assert report["findings"][0].startswith("latency on camera_to_body")
    # Rerun's own reader finds one recomputed world point per replayed detection.
    rows = sum(c.num_rows for c in RrdReader(rrd).stream()
               if c.entity_path == "/points/recomputed/world" and not c.is_static)
    assert rows == 32


def test_report_writes_html(latency_case: tuple[ArmDataset, Path], tmp_path: Path) -> None:
    ds, robot = latency_case
    code = main(["report", str(ds.root), "--episode", "0", "--robot", str(robot), "--out", str(tmp_path),
                 "--bootstrap", "5", "-q"])
    assert code == 0
    page = (tmp_path / "report.html").read_text()
    assert "<td><b>latency</b></td><td>camera_to_body</td><td>-</td><td>+40" in page  # no camera named: the one
    assert page.count("<img ") >= 4  # the plots are embedded


def test_info_on_one_episode_counts_that_episode(latency_case: tuple[ArmDataset, Path],
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    ds, robot = latency_case
    assert main(["info", str(ds.root), "--episode", "1", "--robot", str(robot), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["message_count"] == 30  # episode 1 has 30 frames; the dataset 120
    assert info["duration_s"] == pytest.approx(29 / FPS)


def test_missing_options_are_one_line_errors(latency_case: tuple[ArmDataset, Path], tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    ds, robot = latency_case
    assert main(["attribute", str(ds.root), "--robot", str(robot), "--out", str(tmp_path)]) == 1
    assert "needs --episode N" in capsys.readouterr().err
    assert main(["attribute", str(ds.root), "--episode", "5", "--robot", str(robot), "--out", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.endswith("no episode 5; episodes are 0..1")
    assert len(err.splitlines()) == 1


def test_adapter_plugin(latency_case: tuple[ArmDataset, Path]) -> None:
    ds, robot = latency_case
    adapter = LeRobotAdapter()
    assert adapter.probe(ds.root)
    assert not adapter.probe(robot.parent)
    info = scan_dataset(ds.root)
    assert info.format == "lerobot"
    assert info.message_count == 120
    assert info.end_ns == round(89 / 30 * 1e9)
    state = info.topic("observation.state")
    assert state is not None
    assert (state.rate_hz, state.count) == (30.0, 120)
    loaded = adapter.open(ds.root, ChainConfig(robot={"episode": 1, "config": str(robot)}))
    assert loaded.timeline.metadata["episode"] == 1
    assert len(loaded.timeline.joint_states) == 30 * 7
    with pytest.raises(AdapterError, match="needs an episode"):
        adapter.open(ds.root, ChainConfig(robot={"config": str(robot)}))


def test_tf_over_an_episode(latency_case: tuple[ArmDataset, Path], capsys: pytest.CaptureFixture[str]) -> None:
    """tf2_echo for a LeRobot episode: one transform per joint-state frame of the flange, timeless base."""
    ds, robot = latency_case
    assert main(["tf", str(ds.root), "world", "flange_link", "--episode", "1", "--robot", str(robot),
                 "--series", "-q"]) == 0
    rows = capsys.readouterr().out.strip().splitlines()
    assert rows[0].startswith("stamp_ns,t_rel_s,x,y,z")
    assert len(rows) - 1 == 30  # episode 1: 30 frames
    assert main(["tf", str(ds.root), "world", "flange_link", "--robot", str(robot)]) == 1
    assert "needs --episode N" in capsys.readouterr().err

