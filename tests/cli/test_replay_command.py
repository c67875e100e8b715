"""``framechain replay``: a saved timeline or a recorded log replayed into a Rerun recording (saved, spawned
without a display, streamed to a running viewer), its counts and findings as JSON or text, one line for bad input.

The timeline is the Rerun sink tests' mast-camera scene with the robot's own hop points; recordings are read back
with Rerun's own reader.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from framechain.cli.main import main
from framechain.config.chain import ChainConfig
from framechain.timeline import Timeline
from tests.helpers.rerun_scene import recorded_timeline
from tests.helpers.rerun_server import GrpcServer, received_entities
from tests.helpers.rrd_views import column_values, read_chunks


@pytest.fixture(scope="module")
def recorded() -> Timeline:
    return recorded_timeline()


@pytest.fixture
def saved_timeline(tmp_path: Path, recorded: Timeline) -> Path:
    directory = tmp_path / "scene_timeline"
    recorded.replace(metadata={"chain": {"frames": {"camera": "camera_optical_frame", "body": "base_link",
                                                          "world": "map"}}}).save(directory)
    return directory


def test_cli_replay_saves_and_prints_counts(
    saved_timeline: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cli.rrd"
    assert main(["replay", str(saved_timeline), "--save", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    # Every replayed detection lands on an odometry sample (50 Hz) and a depth frame (20 Hz): no sample used is
    # further from it than the odometry's 20 ms period, the chain's latency budget, so none is stale.
    assert report["counts"] == {"total": 7, "replayed": 5, "rejected": {"extrapolation": 1, "outside_image": 1},
                                "stale": 0}
    assert report["output"] == {"mode": "save", "path": str(out), "url": None, "fell_back": False}
    assert report["frames"] == {"camera": "camera_optical_frame", "body": "base_link", "world": "map"}
    entities = {c.entity_path for c in RrdReader(out).stream()}
    assert "/points/as_run/body" in entities


def test_cli_replay_text_output(saved_timeline: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "text.rrd"
    assert main(["replay", str(saved_timeline), "--save", str(out)]) == 0
    text = capsys.readouterr().out
    assert "7 total, 5 replayed, 2 rejected" in text
    assert "extrapolation 1" in text
    assert "outside_image 1" in text
    assert str(out) in text


def test_cli_replay_spawn_without_display(
    saved_timeline: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.chdir(tmp_path)
    assert main(["replay", str(saved_timeline), "--spawn", "--quiet"]) == 0
    captured = capsys.readouterr()
    assert "no display" in captured.err
    assert "rerun         saved" in captured.out  # --quiet keeps the result, drops progress
    assert (tmp_path / "scene_timeline.rrd").is_file()


def test_cli_replay_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(tmp_path / "missing.mcap"), "--save", str(tmp_path / "x.rrd")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "missing.mcap" in err[0]


@pytest.mark.filterwarnings("ignore:RRD file has no footer:rerun.error_utils.RerunWarning")
def test_cli_replay_connect(
    saved_timeline: Path, grpc_server: GrpcServer, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["replay", str(saved_timeline), "--connect", grpc_server.url, "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["output"] == {"mode": "connect", "path": None, "url": grpc_server.url, "fell_back": False}
    assert "/points/as_run/world" in received_entities(grpc_server)


def test_cli_replay_reads_a_recorded_log(
    recorded: Timeline, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from framechain.adapters import write_log

    chain = ChainConfig.from_dict({
        "frames": {"camera": "camera_optical_frame", "body": "base_link", "world": "map"},
        "topics": {"camera_info": "/camera/camera_info", "detections": "/detections",
                   "depth": "/camera/depth/image_rect_raw"},
        "evidence": {"hops": {"camera": "/debug/point_camera", "body": "/debug/point_body",
                              "world": "/debug/point_world"}, "target": "/grasp_target"},
    })
    log = write_log(recorded, tmp_path / "scene.mcap", container="mcap-ros2", chain=chain)
    chain_file = tmp_path / "chain.yaml"
    chain_file.write_text(chain.to_yaml())
    out = tmp_path / "mcap.rrd"
    assert main(["replay", str(log), "--chain", str(chain_file), "--save", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["source"] == "mcap"
    assert report["counts"]["replayed"] == 5
    assert report["entities"]["/series/error_mm/camera_to_body"] == 5  # as-run matched by stamp
    # Without --chain the frames are suggested, and so are the robot's hop-point topics (found by name).
    assert main(["replay", str(log), "--save", str(tmp_path / "nochain.rrd"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["frames"] == {"camera": "camera_optical_frame", "body": "base_link", "world": "map"}
    assert not any("not used" in note for note in report["notes"])
    assert report["entities"]["/series/error_mm/camera_to_body"] == 5




def test_cli_replay_attribute_logs_the_findings(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from framechain.catalogue import Fault
    from framechain.sim.scene import InjectedFault, SceneSpec, generate

    generated = generate(SceneSpec(duration_s=2.0, width=160, height=120, focal_px=150.0,
                                   faults=(InjectedFault(Fault.MISSING_ROTATION),)))
    directory = tmp_path / "episode"
    generated.timeline.replace(metadata={"chain": generated.chain.to_dict()}).save(directory)
    out = tmp_path / "attributed.rrd"
    assert main(["replay", str(directory), "--save", str(out), "--json"]) == 0  # attribution is on by default
    report = json.loads(capsys.readouterr().out)
    assert report["findings"]
    assert report["findings"][0].startswith("missing_rotation on camera_to_body")
    logged = [r[0] for r in column_values(read_chunks(out), "/log/findings", "TextLog:text")]
    assert logged == report["findings"]
    plain = tmp_path / "plain.rrd"
    assert main(["replay", str(directory), "--no-attribute", "--save", str(plain), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["findings"] == []
    assert "/log/findings" not in read_chunks(plain)




def test_cli_replay_without_output_option_saves_when_headless(
    saved_timeline: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.chdir(tmp_path)
    assert main(["replay", str(saved_timeline)]) == 0
    out = capsys.readouterr().out
    assert f"saved {tmp_path / 'scene_timeline.rrd'}" in out
