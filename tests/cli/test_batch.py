"""framechain batch: a fleet of real written logs into one table and report, resumable, on a pool or Ray."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
import pytest
import yaml
from mcap.reader import make_reader

from framechain.catalogue import Fault
from framechain.cli.main import main
from framechain.fleet import RESULTS_DIR, run_batch
from framechain.sim.logs import write_scene
from framechain.sim.scene import InjectedFault, SceneSpec, generate
from tests.helpers.realdata import STAIRS_BAG, UNITREE

LATENCY_S = -0.03
ANGLE_DEG = 3.0


def _scene(seed: int, *faults: InjectedFault, duration_s: float = 2.0) -> Any:
    return generate(SceneSpec(seed=seed, duration_s=duration_s, width=320, height=240, focal_px=300.0,
                              evidence="hops", faults=faults))


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four MCAPs and a ROS 2 bag written with the real writers, and one log cut short."""
    root = tmp_path_factory.mktemp("fleet") / "logs"
    (root / "day2").mkdir(parents=True)
    write_scene(_scene(1, InjectedFault(Fault.LATENCY, "robot", {"offset_s": LATENCY_S})), root / "latency.mcap")
    write_scene(_scene(2, InjectedFault(Fault.ROTATION_ERROR, "robot", {"angle_deg": ANGLE_DEG, "axis": [0, 1, 0]})),
                root / "rotation.mcap")
    write_scene(_scene(3), root / "day2" / "clean.mcap")
    write_scene(_scene(4, InjectedFault(Fault.LATENCY, "robot", {"offset_s": LATENCY_S})), root / "day2" / "bag",
                container="rosbag2-sqlite")
    whole = (root / "latency.mcap").read_bytes()
    (root / "day2" / "cut.mcap").write_bytes(whole[: len(whole) // 3])  # a recording that stopped early
    (root / "day2" / "notes.txt").write_text("not a log")
    return root


def _rows(out: Path) -> list[dict[str, Any]]:
    return pq.read_table(out / "fleet.parquet").to_pylist()


def _by_name(rows: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    out: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        out.setdefault(Path(row["log"]).name, []).append(row)
    return out


def _mcap_span_s(path: Path) -> float:
    with path.open("rb") as f:
        stats = make_reader(f).get_summary().statistics  # type: ignore[union-attr]
    return (stats.message_end_time - stats.message_start_time) * 1e-9  # type: ignore[union-attr]


def test_batch_writes_the_fleet_table_and_report(fleet: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["batch", str(fleet), "--out", str(out), "-j", "2", "--bootstrap", "0", "-q"]) == 0
    rows = _by_name(_rows(out))
    assert set(rows) == {"latency.mcap", "rotation.mcap", "clean.mcap", "bag", "cut.mcap"}  # notes.txt is no log
    latency = rows["latency.mcap"]
    assert [(r["status"], r["fault"], r["hop"], r["estimate_unit"]) for r in latency] == [
        ("findings", "latency", "body_to_world", "s")]
    assert latency[0]["estimate_value"] == pytest.approx(LATENCY_S, abs=2e-3)
    assert json.loads(latency[0]["estimate_json"])["offset_s"] == pytest.approx(LATENCY_S, abs=2e-3)
    assert latency[0]["span_s"] == pytest.approx(_mcap_span_s(fleet / "latency.mcap"), abs=1e-9)
    assert rows["bag"][0]["fault"] == "latency"  # a ROS 2 bag directory is one log, not walked into
    rotation = rows["rotation.mcap"][0]
    assert (rotation["fault"], rotation["hop"]) == ("rotation_error", "camera_to_body")
    assert rotation["estimate_unit"] == "deg"
    assert abs(rotation["estimate_value"]) == pytest.approx(ANGLE_DEG, abs=0.2)
    clean = rows["clean.mcap"]
    assert [(r["status"], r["fault"], r["finding"]) for r in clean] == [("clean", None, None)]
    cut = rows["cut.mcap"]
    assert len(cut) == 1
    assert cut[0]["status"] in ("error", "nothing_replayed")
    assert cut[0]["error"]
    assert "cut.mcap" in cut[0]["error"]

    html = (out / "fleet_report.html").read_text()
    assert "data:image/png;base64," in html
    assert "rotation_error" in html
    assert "cut.mcap" in html
    md = (out / "fleet_report.md").read_text()
    assert "5 logs: 3 with findings; 1 clean" in md
    for image in ("fleet_faults.png", "fleet_estimates.png"):
        assert f"]({image})" in md
        assert (out / image).stat().st_size > 1000
    stdout = capsys.readouterr().out
    assert "computed 5, kept from an earlier run 0" in stdout


def test_a_rerun_skips_finished_logs_and_redoes_a_changed_one(fleet: Path, tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    shutil.copytree(fleet, logs)
    out = tmp_path / "out"
    first = run_batch([logs], out, jobs=1, bootstrap=0, report_formats=())
    assert first.computed == 5
    mtimes = {p.name: p.stat().st_mtime_ns for p in (out / RESULTS_DIR).glob("*.json")}
    assert len(mtimes) == 5
    again = run_batch([logs], out, jobs=1, bootstrap=0, report_formats=())
    assert (again.computed, again.skipped) == (0, 5)
    assert {p.name: p.stat().st_mtime_ns for p in (out / RESULTS_DIR).glob("*.json")} == mtimes
    os.utime(logs / "rotation.mcap", ns=(time.time_ns(), time.time_ns()))  # the log was rewritten
    third = run_batch([logs], out, jobs=1, bootstrap=0, report_formats=())
    assert (third.computed, third.skipped) == (1, 4)
    assert len(_rows(out)) == 5  # the stale record of the old file is not in the table


def test_a_killed_batch_resumes_without_redoing_finished_logs(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    for seed in range(5):
        write_scene(_scene(10 + seed, InjectedFault(Fault.LATENCY, "robot", {"offset_s": LATENCY_S})),
                    logs / f"episode_{seed}.mcap")
    out = tmp_path / "out"
    results = out / RESULTS_DIR
    argv = [sys.executable, "-m", "framechain", "batch", str(logs), "--out", str(out), "-j", "2", "-q",
            "--bootstrap", "0"]
    batch = subprocess.Popen(argv, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not list(results.glob("*.json")) and time.monotonic() < deadline and batch.poll() is None:
            time.sleep(0.01)
    finally:
        os.killpg(batch.pid, signal.SIGKILL)  # the batch, its fork server and its workers
        batch.wait()
    finished = {p.name: p.stat().st_mtime_ns for p in results.glob("*.json")}
    assert 1 <= len(finished) < 5, "the kill should land after the first log and before the last"
    assert not (out / "fleet.parquet").exists()

    result = run_batch([logs], out, jobs=2, bootstrap=0, report_formats=())
    assert (result.skipped, result.computed) == (len(finished), 5 - len(finished))
    assert {n: (results / n).stat().st_mtime_ns for n in finished} == finished
    assert [r["status"] for r in result.records] == ["findings"] * 5
    assert not list(results.glob(".*.tmp"))  # no half-written record left behind


def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="finds the worker processes through /proc")
def test_a_dead_worker_costs_one_row_and_the_rerun_redoes_only_it(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    # The long log goes to one worker first; the other works through the short ones meanwhile (long enough to be
    # running still when the first short one is done, however the test's own process is scheduled).
    write_scene(_scene(20, InjectedFault(Fault.LATENCY, "robot", {"offset_s": LATENCY_S}), duration_s=120.0),
                logs / "a_long.mcap")
    for seed in range(4):
        write_scene(_scene(21 + seed), logs / f"b_short_{seed}.mcap")
    out = tmp_path / "out"
    results = out / RESULTS_DIR
    argv = [sys.executable, "-m", "framechain", "batch", str(logs), "--out", str(out), "-j", "2", "-q",
            "--bootstrap", "200"]
    batch = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    killed = None
    try:
        deadline = time.monotonic() + 120
        while killed is None and time.monotonic() < deadline and batch.poll() is None:
            done = [json.loads(p.read_text()) for p in results.glob("*.json")] if results.is_dir() else []
            if done:
                free = {r["pid"] for r in done}
                workers = [w for server in _children(batch.pid) for w in _children(server)]
                busy = [w for w in workers if w not in free]
                assert len(busy) <= 1, (workers, free)
                if busy:  # none: the worker that took the long log has not been seen yet (a process just started)
                    os.kill(busy[0], signal.SIGKILL)
                    killed = busy[0]
            time.sleep(0.01)
        _stdout, stderr = batch.communicate(timeout=120)
    finally:
        if batch.poll() is None:
            batch.kill()
            batch.communicate()  # its pipes closed here, not by the collector during another test
    assert killed is not None
    assert batch.returncode == 0, stderr
    rows = _by_name(_rows(out))
    long_row = rows.pop("a_long.mcap")[0]
    assert long_row["status"] == "crashed"
    assert f"exit code {-signal.SIGKILL}" in long_row["error"]
    assert {r[0]["status"] for r in rows.values()} == {"clean"}
    assert len(rows) == 4
    kept = {p.name: p.stat().st_mtime_ns for p in results.glob("*.json")}

    result = run_batch([logs], out, jobs=2, bootstrap=200, report_formats=())
    assert (result.computed, result.skipped) == (1, 4)
    assert _by_name(_rows(out))["a_long.mcap"][0]["fault"] == "latency"
    changed = [n for n, t in kept.items() if (results / n).stat().st_mtime_ns != t]
    assert len(changed) == 1  # only the crashed log's record was written again


def test_a_lerobot_dataset_is_one_unit_per_episode(tmp_path: Path) -> None:
    import numpy as np

    from tests.helpers.lerobot_scene import target_world, write_arm_dataset, write_detection_table, write_robot_yaml

    delay_s = 0.04
    ds = write_arm_dataset(tmp_path / "ds", version="v3.0", lengths=(90, 30), camera_delay_s=delay_s)
    write_detection_table(tmp_path / "det.parquet", ds, 0, frames=np.arange(14, 77, 2))
    robot = write_robot_yaml(tmp_path, detections=[{"table": "det.parquet"}], chain={
        "camera": "wrist", "latency_budget_s": 0.02,
        "evidence": {"reference_point": [float(x) for x in target_world()], "static_target": True},
    })
    out = tmp_path / "out"
    result = run_batch([ds.root], out, robot=robot, jobs=1, bootstrap=0, report_formats=("md",))
    rows = {r["episode"]: r for r in _rows(out)}
    assert set(rows) == {0, 1}
    assert (rows[0]["status"], rows[0]["fault"], rows[0]["hop"]) == ("findings", "latency", "camera_to_body")
    assert rows[0]["estimate_value"] == pytest.approx(delay_s, abs=2e-3)
    assert rows[0]["span_s"] == pytest.approx(89 / 30, abs=1e-6)  # frames 0..89 at 30 fps
    assert rows[1]["status"] == "nothing_replayed"  # the detections are episode 0's only
    assert result.computed == 2

    only = run_batch([ds.root], tmp_path / "one", robot=robot, episodes=[1], bootstrap=0, report_formats=())
    assert [r["episode"] for r in only.records] == [1]
    without = run_batch([ds.root], tmp_path / "none", bootstrap=0, report_formats=())
    assert [(r["status"], r["episode"]) for r in without.records] == [("error", None)]
    assert "needs --robot" in without.records[0]["error"]


def test_ray_engine_gives_the_local_engine_s_table(fleet: Path, tmp_path: Path) -> None:
    ray = pytest.importorskip("ray")
    local = run_batch([fleet], tmp_path / "local", jobs=1, bootstrap=0, report_formats=())
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)  # never a running cluster
    try:
        remote = run_batch([fleet], tmp_path / "ray", engine="ray", bootstrap=0, report_formats=())
    finally:
        ray.shutdown()
    columns = ["unit", "status", "fault", "hop", "estimate_json", "share", "start_ns", "end_ns"]
    assert pq.read_table(remote.table_path).select(columns).to_pylist() == pq.read_table(
        local.table_path).select(columns).to_pylist()
    assert {r["pid"] for r in remote.records}.isdisjoint({os.getpid()})  # ran in Ray's workers


def test_realdata_fleet(realdata: Path, tmp_path: Path) -> None:
    """The ROS logs and the LeRobot datasets of ../shared/realdata: every log one row, a table and a report."""
    unitree = realdata / UNITREE
    names = json.loads((unitree / "meta" / "info.json").read_text())["features"]["observation.state"]["names"][0]
    arm = names[:7]
    links = "".join(f'<link name="l{i}"/>' for i in range(len(arm) + 1))
    joints = "".join(f'<joint name="{n}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
                     f'<origin xyz="0.1 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3"/></joint>'
                     for i, n in enumerate(arm))
    (tmp_path / "arm.urdf").write_text(f'<?xml version="1.0"?><robot name="arm">{links}{joints}</robot>')
    robot = tmp_path / "robot.yaml"
    robot.write_text(json.dumps({
        "urdf": "arm.urdf", "default_unit": "rad", "joints": {n: n for n in arm},
        "cameras": {"head": {"intrinsics": {"fx": 300, "fy": 300, "cx": 320, "cy": 240, "width": 640, "height": 480},
                             "mount": {"parent": "l7", "xyz": [0.05, 0, 0], "rpy": [0, 0, 0], "optical": False},
                             "video_key": "observation.images.cam_high"}},
    }))
    out = tmp_path / "out"
    assert main(["batch", str(realdata), "--out", str(out), "--robot", str(robot), "--episodes", "0-2",
                 "-j", "2", "--bootstrap", "0", "-q"]) == 0
    rows = _rows(out)
    ros_logs = {str(p) for p in realdata.rglob("*") if p.suffix in (".bag", ".mcap")} | {
        str(p.parent) for p in realdata.rglob("metadata.yaml")}
    assert {r["log"] for r in rows if r["episode"] is None} == ros_logs
    episodes = sorted((Path(r["log"]).name, r["episode"]) for r in rows if r["episode"] is not None)
    assert episodes == [(d, e) for d in ("gr00t_pick_n_place_v20", "unitree_g1_v21") for e in range(3)]
    assert all(r["status"] and (r["status"] in ("findings", "clean") or r["error"]) for r in rows)
    tagslam = next(r for r in rows if r["log"].endswith(STAIRS_BAG))
    assert tagslam["span_s"] == pytest.approx(86.4, abs=0.1)  # the bag spans 86.4 s (rosbags' own reader)
    assert (out / "fleet_report.html").stat().st_size > 0
    assert (out / "fleet_report.md").stat().st_size > 0


def test_bad_inputs_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["batch", str(tmp_path / "missing"), "--out", str(tmp_path / "out")]) == 1
    assert capsys.readouterr().err.strip().endswith("missing: no such file or directory")
    (tmp_path / "empty").mkdir()
    assert main(["batch", str(tmp_path / "empty"), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "no logs in this directory" in err
    with pytest.raises(SystemExit) as exc:
        main(["batch", str(tmp_path), "--out", str(tmp_path / "out"), "--episodes", "3-1"])
    assert exc.value.code == 2


def test_batch_help_documents_exit_codes(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["batch", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "exit codes:" in text
    assert "\n  1    bad input" in text
    assert "--engine {local,ray}" in text


def test_fleet_table_rows_and_the_estimates_spread() -> None:
    from framechain.fleet import fleet_table
    from framechain.sinks.fleet_report import estimate_spread, fleet_logs, not_analysed_reasons

    def record(name: str, status: str, *offsets_s: float) -> dict[str, Any]:
        findings = [{"fault": "latency", "hop": "body_to_world", "estimate_name": "offset_s", "estimate_value": v,
                     "estimate_text": f"{v * 1e3:+.1f} ms", "share": 1.0} for v in offsets_s]
        return {"key": name, "log": f"/fleet/{name}.mcap", "unit": name, "status": status, "findings": findings,
                "start_ns": 1_000_000_000, "end_ns": 3_500_000_000}

    broken = [{**record(name, "error"), "error": f"/fleet/{name}.mcap: the file is empty (0 bytes)"} for name in "xy"]
    table = fleet_table([record("a", "findings", -0.02), record("b", "findings", -0.03), record("c", "clean"),
                         record("d", "findings", -0.05), *broken])
    assert table.num_rows == 6
    assert table.column("span_s").to_pylist() == [2.5] * 6
    assert table.column("finding").to_pylist() == [1, 1, None, 1, None, None]
    (reason,) = not_analysed_reasons(fleet_logs(table))
    assert (reason.status, reason.logs, reason.reason) == ("error", 2, "the file is empty (0 bytes)")
    (row,) = estimate_spread(fleet_logs(table))
    assert (row.fault, row.logs, row.unit) == ("latency", 3, "ms")
    # Sorted -50, -30, -20 ms; linear percentiles: p5 at index 0.1, p95 at index 1.9.
    assert (row.median, row.lo, row.hi) == pytest.approx((-30.0, -50.0, -20.0))
    assert (row.p5, row.p95) == pytest.approx((-50.0 + 0.1 * 20.0, -30.0 + 0.9 * 10.0))
    # The texts are format_estimate's (the median log's own) and format_interval's, as attribute prints.
    assert row.median_text == "-30.0 ms"
    assert row.p5_p95_text == "-48.00 .. -21.00 ms"
    assert row.range_text == "-50.00 .. -20.00 ms"


def test_fleet_spread_keeps_the_text_of_estimates_without_a_number() -> None:
    """A frame swap has no scalar: the fleet shows its text (``used: camera_link``), not "-"."""
    from framechain.fleet import fleet_table
    from framechain.sinks.fleet_report import estimate_spread, fleet_logs

    swap = "looked up camera_link instead of camera_color_optical_frame"
    finding = {"fault": "axis_flip", "hop": "camera_to_body", "estimate_name": None, "estimate_value": None,
               "estimate_text": swap, "share": 0.9}
    records = [{"key": k, "log": f"/fleet/{k}.mcap", "unit": k, "status": "findings", "findings": [finding],
                "start_ns": 0, "end_ns": 1_000_000_000} for k in "ab"]
    (row,) = estimate_spread(fleet_logs(fleet_table(records)))
    assert (row.logs, row.median, row.median_text, row.p5_p95_text) == (2, None, swap, "-")


# -- each log's own chain, framechain's outputs skipped, paths as given ----------------------------------
def _write_chain(path: Path, chain: Any, *, evidence: bool) -> Path:
    raw = chain.to_dict()
    if not evidence:
        raw.pop("evidence", None)
    path.write_text(yaml.safe_dump(raw))
    return path


def test_each_log_uses_the_chain_beside_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """chain.yaml in the log's folder, <log name>.chain.yaml beside it, --chain for the others: the chain
    decides what is measured (the robot's hop points, or no evidence), and the table says which was used."""
    logs = tmp_path / "logs"
    for name in ("a", "b", "c"):
        (logs / name).mkdir(parents=True)
    fault = InjectedFault(Fault.LATENCY, "robot", {"offset_s": LATENCY_S})
    scenes = {name: _scene(30 + i, fault) for i, name in enumerate("abc")}
    for name, scene in scenes.items():
        write_scene(scene, logs / name / f"{name}.mcap")
    folder_chain = _write_chain(logs / "a" / "chain.yaml", scenes["a"].chain, evidence=True)
    named_chain = _write_chain(logs / "b" / "b.chain.yaml", scenes["b"].chain, evidence=False)
    default = _write_chain(tmp_path / "default.yaml", scenes["c"].chain, evidence=False)
    out = tmp_path / "out"
    assert main(["batch", str(logs), "--out", str(out), "--chain", str(default), "-j", "1", "--bootstrap", "0",
                 "-q"]) == 0
    rows = {Path(r["log"]).name: r for r in _rows(out)}
    assert {n: (r["chain"], r["chain_suggested"]) for n, r in rows.items()} == {
        "a.mcap": (str(folder_chain), False), "b.mcap": (str(named_chain), False), "c.mcap": (str(default), False)}
    assert (rows["a.mcap"]["status"], rows["a.mcap"]["metric"], rows["a.mcap"]["fault"]) == (
        "findings", "logged_hops", "latency")
    assert rows["b.mcap"]["status"] == rows["c.mcap"]["status"] == "no_evidence"  # their chains name no evidence
    stdout = capsys.readouterr().out
    assert f"Chains: {default} (1 log); {folder_chain} (1 log); {named_chain} (1 log)." in stdout
    md = (out / "fleet_report.md").read_text()
    assert f"| {folder_chain} |" in md
    # Without --chain the log that has none beside it gets its suggested chain (which finds the hop points).
    assert main(["batch", str(logs), "--out", str(tmp_path / "out2"), "-j", "1", "--bootstrap", "0", "-q"]) == 0
    rows = {Path(r["log"]).name: r for r in _rows(tmp_path / "out2")}
    assert (rows["c.mcap"]["chain"], rows["c.mcap"]["chain_suggested"], rows["c.mcap"]["fault"]) == (
        None, True, "latency")
    assert rows["b.mcap"]["chain"] == str(named_chain)


def test_framechain_exports_are_not_logs(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                        monkeypatch: pytest.MonkeyPatch) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    scene = _scene(40, InjectedFault(Fault.LATENCY, "robot", {"offset_s": LATENCY_S}))
    log = write_scene(scene, logs / "episode.mcap")
    chain = _write_chain(tmp_path / "chain.yaml", scene.chain, evidence=True)
    export = logs / "episode.annotated.mcap"
    assert main(["export", str(log), "--chain", str(chain), "--out", str(export), "--no-attribute", "-q"]) == 0
    with export.open("rb") as f:  # the export marks itself: an MCAP metadata record
        (record,) = [m for m in make_reader(f).iter_metadata() if m.name == "framechain"]
    assert record.metadata["command"] == "export"
    assert record.metadata["source"] == str(log)
    capsys.readouterr()
    out = tmp_path / "out"
    result = run_batch([logs], out, jobs=1, bootstrap=0, report_formats=("md",))
    assert [Path(r["log"]).name for r in result.records] == ["episode.mcap"]  # one row: the recording's
    assert result.notes == [f"{export} skipped: written by framechain {record.metadata['version']} export of {log}, "
                            "not a recording"]
    assert f"note: {result.notes[0]}" in (out / "fleet_report.md").read_text()
    monkeypatch.setenv("FRAMECHAIN_PROGRESS_INTERVAL_S", "0")  # every report a line
    assert main(["batch", str(logs), "--out", str(tmp_path / "out2"), "-j", "1", "--bootstrap", "0"]) == 0
    captured = capsys.readouterr()
    assert f"note: {result.notes[0]}" in captured.out
    # Not a terminal: the progress is plain lines, as a CI log needs them.
    assert captured.err.splitlines()[:2] == ["framechain: attributing logs 0% (0 of 1 logs)",
                                             "framechain: attributing logs 100% (1 of 1 logs)"]


def test_paths_stay_as_given_through_a_symlinked_folder(fleet: Path, tmp_path: Path) -> None:
    link = tmp_path / "shared"
    link.symlink_to(fleet)
    result = run_batch([link], tmp_path / "out", jobs=1, bootstrap=0, report_formats=())
    logs = {r["log"] for r in _rows(tmp_path / "out")}
    assert logs == {str(link / "latency.mcap"), str(link / "rotation.mcap"), str(link / "day2" / "clean.mcap"),
                    str(link / "day2" / "bag"), str(link / "day2" / "cut.mcap")}
    # The same logs through the resolved path are the same units: nothing is computed again.
    again = run_batch([fleet.resolve()], tmp_path / "out", jobs=1, bootstrap=0, report_formats=())
    assert (again.computed, again.skipped) == (0, result.computed)
