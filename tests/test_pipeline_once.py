"""One run, computed once: every command that reads a log reads it once, replays once and aligns once.

Counted where the work happens: the readers' decode pass (``McapLog.read``, ``RosbagsLog.read``), the
replay (``framechain.replay.replay``) and the alignment of the logged evidence (``align_evidence``),
wherever a module holds them. Covered: a chain given, a chain suggested (whose evidence topics and
detections topic used to cost a second read), and a log that cannot be attributed (which used to
cost a third replay).
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from framechain import pipeline
from framechain.adapters.formats.mcap.reader import McapLog
from framechain.adapters.formats.rosbag.reader import RosbagsLog
from framechain.analysis.evidence.alignment import align_evidence
from framechain.catalogue import Fault
from framechain.cli.main import main
from framechain.replay import replay
from framechain.sim.logs import write_scene
from framechain.sim.scene import InjectedFault, SceneSpec, generate

Counts = Counter[str]


@pytest.fixture
def counts(monkeypatch: pytest.MonkeyPatch) -> Counts:
    """How many decode passes, replays and alignments the code under test made."""
    seen: Counts = Counter()

    def counting(name: str, original: Callable[..., Any]) -> Callable[..., Any]:
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            seen[name] += 1
            return original(*args, **kwargs)

        return wrapper

    monkeypatch.setattr(McapLog, "read", counting("read", McapLog.read))
    monkeypatch.setattr(RosbagsLog, "read", counting("read", RosbagsLog.read))
    for name, original in (("replay", replay), ("align", align_evidence)):
        wrapped = counting(name, original)
        for module in list(sys.modules.values()):  # every module that imported it by name
            if module is not None and module.__name__.startswith("framechain") \
                    and getattr(module, original.__name__, None) is original:
                monkeypatch.setattr(module, original.__name__, wrapped)
    return seen


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A real MCAP with the robot's hop points (a suggested chain gives them their roles) and its chain."""
    out = tmp_path_factory.mktemp("once")
    scene = generate(SceneSpec(seed=2, duration_s=2.0, width=160, height=120, focal_px=150.0, evidence="hops",
                               faults=(InjectedFault(Fault.LATENCY, "robot", {"offset_s": -0.03}),)))
    path = write_scene(scene, out / "episode.mcap")
    chain = out / "given.yaml"  # not chain.yaml: batch would take a chain.yaml beside the log over --chain
    chain.write_text(scene.chain.to_yaml())
    # Every label declared moving: every observation rejected, nothing to attribute.
    labels = tuple(sorted(set(scene.timeline.observations.label.tolist())))
    ignored = out / "ignored.yaml"
    ignored.write_text(replace(scene.chain, evidence=replace(scene.chain.evidence, ignore_labels=labels)).to_yaml())
    return path, chain


def _once(counts: Counts) -> None:
    assert counts == {"read": 1, "replay": 1, "align": 1}, dict(counts)


def test_the_suggested_chain_is_worked_out_from_the_one_read(log: tuple[Path, Path], counts: Counts) -> None:
    path, _ = log
    made = pipeline.run(path, bootstrap=0)
    _once(counts)
    assert made.chain_suggested
    assert made.chain.evidence_topics()  # what used to cost a second read: the hop points given roles
    assert made.attributed().metric == "logged_hops"
    assert made.findings[0].fault == Fault.LATENCY
    # The same run as the chain written out gives, read with that chain.
    given = pipeline.run(path, made.chain, bootstrap=0)
    assert given.attributed().to_json()["findings"] == made.attributed().to_json()["findings"]


@pytest.mark.parametrize("chain", ["given", "suggested", "not attributable"])
def test_attribute_reads_once_and_replays_once(log: tuple[Path, Path], chain: str, tmp_path: Path,
                                               counts: Counts, capsys: pytest.CaptureFixture[str]) -> None:
    path, chain_file = log
    args = {"given": ["--chain", str(chain_file)], "suggested": [],
            "not attributable": ["--chain", str(chain_file.with_name("ignored.yaml"))]}[chain]
    code = main(["attribute", str(path), *args, "--out", str(tmp_path / "out"), "--bootstrap", "0", "-q"])
    _once(counts)
    if chain == "not attributable":
        assert code == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1
        assert "all rejected: ignored_label" in err[0]
    else:
        assert code == 0
        assert json.loads((tmp_path / "out" / "attribution.json").read_text())["findings"][0]["fault"] == "latency"


@pytest.mark.parametrize("chain", ["given", "suggested", "not attributable"])
def test_replay_save_reads_once_and_replays_once(log: tuple[Path, Path], chain: str, tmp_path: Path,
                                                 counts: Counts, capsys: pytest.CaptureFixture[str]) -> None:
    path, chain_file = log
    args = {"given": ["--chain", str(chain_file)], "suggested": [],
            "not attributable": ["--chain", str(chain_file.with_name("ignored.yaml"))]}[chain]
    assert main(["replay", str(path), *args, "--save", str(tmp_path / "r.rrd"), "--json", "-q"]) == 0
    _once(counts)
    report = json.loads(capsys.readouterr().out)
    assert (tmp_path / "r.rrd").stat().st_size > 0
    if chain == "not attributable":
        assert report["counts"]["replayed"] == 0
        assert report["findings"] == []
    else:
        assert report["findings"][0].startswith("latency on body_to_world")


@pytest.mark.parametrize("chain", ["given", "suggested", "not attributable"])
def test_export_reads_once_and_replays_once(log: tuple[Path, Path], chain: str, tmp_path: Path,
                                            counts: Counts, capsys: pytest.CaptureFixture[str]) -> None:
    path, chain_file = log
    args = {"given": ["--chain", str(chain_file)], "suggested": [],
            "not attributable": ["--chain", str(chain_file.with_name("ignored.yaml"))]}[chain]
    assert main(["export", str(path), *args, "--out", str(tmp_path / "a.mcap"), "--json", "-q"]) == 0
    _once(counts)  # the copy of the log's own messages into the export is a copy, not a decode pass
    report = json.loads(capsys.readouterr().out)
    assert report["findings"] == (0 if chain == "not attributable" else 1)
    if chain == "not attributable":  # export applies ignore_labels as every other command does
        assert report["observations"]["rejected"] == {"ignored_label": report["observations"]["total"]}


@pytest.mark.parametrize("chain", ["given", "suggested", "not attributable"])
def test_batch_of_one_log_reads_once_and_replays_once(log: tuple[Path, Path], chain: str, tmp_path: Path,
                                                      counts: Counts) -> None:
    import pyarrow.parquet as pq

    path, chain_file = log
    args = {"given": ["--chain", str(chain_file)], "suggested": [],
            "not attributable": ["--chain", str(chain_file.with_name("ignored.yaml"))]}[chain]
    assert main(["batch", str(path), *args, "--out", str(tmp_path / "b"), "-j", "1", "--bootstrap", "0",
                 "--format", "none", "-q"]) == 0
    _once(counts)
    rows = pq.read_table(tmp_path / "b" / "fleet.parquet").to_pylist()
    assert [r["status"] for r in rows] == (["nothing_replayed"] if chain == "not attributable" else ["findings"])


def test_attribute_starts_its_renderers_once_the_log_is_read(log: tuple[Path, Path], tmp_path: Path, counts: Counts,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    from framechain.sinks import plots

    monkeypatch.setenv(plots.RENDERERS_VARIABLE, "1")
    started: list[dict[str, int]] = []
    start = plots._Pool.start

    def noting_when(pool: Any) -> None:
        if not pool.started:
            started.append(dict(counts))  # what the run had done when the renderer started
        start(pool)

    monkeypatch.setattr(plots._Pool, "start", noting_when)
    path, chain_file = log
    assert main(["attribute", str(path), "--chain", str(chain_file), "--out", str(tmp_path / "out"),
                 "--bootstrap", "0", "-q"]) == 0
    assert started == [{"read": 1}]  # after the read (its two threads), before the replay
    assert (tmp_path / "out" / "report.html").stat().st_size > 0
    # A log that cannot be read starts none.
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap")
    assert main(["attribute", str(bad), "--chain", str(chain_file), "--out", str(tmp_path / "bad"), "-q"]) == 1
    assert len(started) == 1


def test_attribute_of_a_lerobot_episode_starts_one_renderer_at_once(tmp_path: Path, so101_urdf: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """Its read is one thread and its cameras then take both cores: one renderer process, started before the read,
    and the twin it forks draw its two figures per camera (the variable unset: the command's own choice)."""
    from framechain.adapters.lerobot import adapter
    from framechain.sim.lerobot_video import VideoDatasetSpec, generate_video_dataset, write_robot_yaml
    from framechain.sinks import plots

    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(
        so101_urdf, seed=3, episodes=1, duration_s=2.0, fps=15, codec="mpeg4", width=96, height=96, focal_px=60.0))
    robot = write_robot_yaml(truth, tmp_path / "robot.yaml")
    monkeypatch.delenv(plots.RENDERERS_VARIABLE, raising=False)
    events: list[str] = []
    start, open_dataset = plots._Pool.start, adapter.open_dataset

    def noting_start(pool: Any) -> None:
        if not pool.started:
            events.append(f"{pool._workers} renderer(s), twins {pool._twins}")
        start(pool)

    def noting_read(*args: Any, **kwargs: Any) -> Any:
        events.append("read")
        return open_dataset(*args, **kwargs)

    monkeypatch.setattr(plots._Pool, "start", noting_start)
    monkeypatch.setattr(adapter, "open_dataset", noting_read)
    assert main(["attribute", str(truth.root), "--episode", "0", "--robot", str(robot), "--out", str(tmp_path / "out"),
                 "--bootstrap", "0", "-q"]) == 0
    assert plots.EPISODE_RENDERERS == 2
    assert events == ["2 renderer(s), twins True", "read"]
    assert list((tmp_path / "out").glob("rotation_rate_*.png"))


def test_attribute_hands_its_figures_to_the_renderers_before_writing_its_files(
        log: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from framechain.sinks import plots, report

    monkeypatch.setenv(plots.RENDERERS_VARIABLE, "1")
    events: list[str] = []
    submit, write = plots._Pool.submit, report.write_attribution

    def submitting(pool: Any, sketch: Any) -> Any:
        events.append("figure")
        return submit(pool, sketch)

    def writing(*args: Any, **kwargs: Any) -> Any:
        events.append("write")
        return write(*args, **kwargs)

    monkeypatch.setattr(plots._Pool, "submit", submitting)
    monkeypatch.setattr(report, "write_attribution", writing)
    path, chain_file = log
    assert main(["attribute", str(path), "--chain", str(chain_file), "--out", str(tmp_path / "out"),
                 "--bootstrap", "0", "-q"]) == 0
    # Every figure is being drawn while the attribution's files are written, none is asked for after.
    assert events.count("figure") >= 4
    assert events.index("write") == events.count("figure")
    assert (tmp_path / "out" / "error_per_hop.png").read_bytes().startswith(b"\x89PNG")
