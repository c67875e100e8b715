"""The command line: exit codes, one-line errors, and the main jobs end to end on real written logs."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from framechain.catalogue import Fault
from framechain.cli.main import main
from framechain.sim.logs import write_scene
from framechain.sim.scene import InjectedFault, SceneSpec, generate

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def latency_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A small MCAP written with the real writer: 40 ms pose latency, robot's hop points logged."""
    out = tmp_path_factory.mktemp("latency")
    spec = SceneSpec(seed=11, duration_s=4.0, width=320, height=240, focal_px=300.0, depth_images=True,
                     evidence="hops", faults=(InjectedFault(Fault.LATENCY, "robot", {"offset_s": -0.04}),))
    scene = generate(spec)
    log = write_scene(scene, out / "episode.mcap")
    chain = out / "chain.yaml"
    chain.write_text(scene.chain.to_yaml())
    return log, chain


def test_help_lists_commands_and_exit_codes(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for command in ("info", "tf", "replay", "attribute", "report", "batch", "export", "demo", "lab"):
        assert command in text
    assert "exit codes" in text
    assert "bad input" in text


@pytest.mark.parametrize("command", [["info"], ["tf"], ["replay"], ["attribute"], ["report"], ["batch"], ["export"],
                                     ["demo"], ["lab"], ["lab", "tilt"]])
def test_every_command_documents_its_exit_codes(command: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main([*command, "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "exit codes:" in text
    assert "\n  1    bad input" in text  # laid out as a table, not wrapped into the prose


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    """The version the package was installed with (its metadata, written by the build)."""
    from importlib.metadata import version

    with pytest.raises(SystemExit):
        main(["--version"])
    assert capsys.readouterr().out.strip() == f"framechain {version('framechain')}"


def test_lab_tilt_numbers(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["lab", "tilt", "--max-pitch", "5", "--depths", "0.5,1", "--json"]) == 0
    rows = {(r["pitch_deg"], r["depth_m"]): r["error_m"] for r in json.loads(capsys.readouterr().out)}
    # A point straight ahead at depth Z swings by the chord 2 Z sin(pitch / 2) when the pitch is lost.
    assert rows[(1.0, 0.5)] == pytest.approx(2 * 0.5 * math.sin(math.radians(0.5)), rel=1e-9)
    assert rows[(5.0, 1.0)] == pytest.approx(2 * 1.0 * math.sin(math.radians(2.5)), rel=1e-9)
    assert 0.0086 < rows[(1.0, 0.5)] < 0.0088
    assert 0.086 < rows[(5.0, 1.0)] < 0.088


def test_lab_tilt_bad_depths_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["lab", "tilt", "--depths", "x"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "--depths" in err


def test_attribute_writes_the_contract(latency_log: tuple[Path, Path], tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    log, chain = latency_log
    out = tmp_path / "out"
    assert main(["attribute", str(log), "--chain", str(chain), "--out", str(out), "--format", "json,md",
                 "--bootstrap", "5", "-q"]) == 0
    doc = json.loads((out / "attribution.json").read_text())
    assert doc["source"]["format"] == "mcap"
    assert doc["source"]["path"] == str(log)
    top = doc["findings"][0]
    assert (top["fault"], top["hop"]) == ("latency", "body_to_world")
    assert top["estimate"]["offset_s"] == pytest.approx(-0.04, abs=0.002)
    counts = doc["observations"]
    assert counts["replayed"] + sum(counts["rejected"].values()) == counts["total"]
    table = pq.read_table(out / "evidence.parquet")
    assert table.num_rows == 3 * counts["total"]  # one row per observation and hop
    assert set(table.column("hop").to_pylist()) == {"pixel_to_camera", "camera_to_body", "body_to_world"}
    # Only the pose was late: the first two hops agree with the robot, the last one carries the whole error.
    frame = table.to_pandas()
    upstream = frame[frame.hop != "body_to_world"]
    assert float(upstream.hop_error_m.max()) < 1e-6  # float32 depth pixels in the log: sub-micrometre
    last = frame[frame.hop == "body_to_world"]
    np.testing.assert_allclose(last.hop_error_m, last.chain_error_m, atol=1e-6)
    assert float(last.hop_error_m.median()) > 0.005
    # Every edge's samples: the demo chain has a static mount and map -> odom -> base_link.
    samples = pq.read_table(out / "samples.parquet").to_pandas()
    assert len(samples) == counts["total"] * samples.groupby(["hop", "parent", "child"]).ngroups
    world_edges = samples[samples.hop == "body_to_world"]
    assert set(zip(world_edges.parent, world_edges.child, strict=True)) == {("map", "odom"), ("odom", "base_link")}
    joined = world_edges.merge(last[["obs_id", "stamp_ns"]], on="obs_id")
    np.testing.assert_array_equal(joined.gap_before_ns + joined.sample_before_ns, joined.stamp_ns)
    assert (joined.sample_before_ns <= joined.stamp_ns).all()
    assert (joined.stamp_ns <= joined.sample_after_ns).all()
    inputs = json.loads((out / "inputs.json").read_text())
    assert inputs["latency_budget_s"] == 0.02
    assert inputs["metric"]["name"] == "logged_hops"
    report = (out / "report.md").read_text()
    assert report.startswith("# framechain report")
    assert not (out / "report.html").exists()
    # The per-hop summary names where the error sits: the world hop departs by the chain error.
    hops = {r["hop"]: r for r in doc["hops"]}
    assert hops["body_to_world"]["departure_m"]["median"] == pytest.approx(float(last.hop_error_m.median()), abs=1e-6)
    assert hops["camera_to_body"]["departure_m"]["max"] < 1e-6
    assert hops["body_to_world"]["faults"] == ["latency"]
    assert "### Per hop" in report
    assert f"| body_to_world | {hops['body_to_world']['departure_m']['median'] * 1e3:.1f} mm" in report


def test_a_chain_topic_missing_from_the_log_is_a_note(latency_log: tuple[Path, Path], tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    log, chain = latency_log
    typo = tmp_path / "chain.yaml"
    typo.write_text(chain.read_text().replace("/debug/point_body", "/debug/point_bdy"))
    out = tmp_path / "out"
    assert main(["attribute", str(log), "--chain", str(typo), "--out", str(out), "--bootstrap", "0"]) == 0
    note = "topic /debug/point_bdy: named by the chain as evidence hop_body but not in the log"
    assert f"note: {note}" in capsys.readouterr().out
    assert note in json.loads((out / "attribution.json").read_text())["notes"]
    assert note in (out / "report.md").read_text()


def test_attribute_without_chain_prints_the_suggestion(latency_log: tuple[Path, Path], tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    log, _ = latency_log
    assert main(["attribute", str(log), "--out", str(tmp_path / "o"), "--bootstrap", "0", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["frames"]["camera"] == "camera_optical_frame"
    # The suggestion found the robot's /debug/point_* topics, so the latency is found without a chain file.
    assert doc["error_m"]["metric"] == "logged_hops"
    assert (doc["findings"][0]["fault"], doc["findings"][0]["hop"]) == ("latency", "body_to_world")


def test_unknown_chain_key_is_one_line_error(latency_log: tuple[Path, Path], tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    log, _ = latency_log
    bad = tmp_path / "chain.yaml"
    bad.write_text("frames: {camera: c, body: b, world: w}\nevidence: {tagret: /x}\n")
    assert main(["attribute", str(log), "--chain", str(bad), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "tagret" in err
    assert str(bad) in err


@pytest.mark.parametrize(("edit", "expected"), [
    (("body: base_link", "body: base_lnk"),
     "body frame 'base_lnk' is in no transform of the log; did you mean 'base_link'"),
    (("static_target", "reference_point: [a, b, c]\n  static_target"), "reference_point must be [x, y, z]"),
    # world may equal body (a body that does not move), never the camera
    (("body: base_link", "body: camera_optical_frame"), "must differ from body 'camera_optical_frame'"),
])
def test_chain_mistakes_are_named(latency_log: tuple[Path, Path], tmp_path: Path, edit: tuple[str, str],
                                  expected: str, capsys: pytest.CaptureFixture[str]) -> None:
    log, chain = latency_log
    text = chain.read_text()
    assert edit[0] in text
    bad = tmp_path / "chain.yaml"
    bad.write_text(text.replace(edit[0], edit[1], 1))
    assert main(["attribute", str(log), "--chain", str(bad), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert expected in err


def test_options_that_do_not_apply_are_refused(latency_log: tuple[Path, Path], tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    log, chain = latency_log
    args = ["attribute", str(log), "--chain", str(chain), "--out", str(tmp_path / "o")]
    assert main([*args, "--episode", "3"]) == 1
    assert "--episode and --robot are for LeRobot datasets" in capsys.readouterr().err
    with pytest.raises(SystemExit) as usage:
        main([*args, "--bootstrap", "-3"])
    assert usage.value.code == 2
    assert "--bootstrap: must be 0 or more" in capsys.readouterr().err


def test_out_that_is_a_file_is_one_line(latency_log: tuple[Path, Path], tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    log, chain = latency_log
    (tmp_path / "report.md").write_text("x")
    assert main(["attribute", str(log), "--chain", str(chain), "--out", str(tmp_path / "report.md")]) == 1
    assert "exists and is not a directory" in capsys.readouterr().err


def test_empty_chain_file_is_named(latency_log: tuple[Path, Path], tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    log, _ = latency_log
    empty = tmp_path / "chain.yaml"
    empty.write_text("")
    assert main(["attribute", str(log), "--chain", str(empty), "--out", str(tmp_path / "o")]) == 1
    assert f"{empty}: the chain configuration is empty" in capsys.readouterr().err


def test_missing_log_is_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["attribute", str(tmp_path / "nope.mcap"), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "nope.mcap" in err


def test_report_html_is_self_contained(latency_log: tuple[Path, Path], tmp_path: Path) -> None:
    log, chain = latency_log
    out = tmp_path / "report"
    assert main(["report", str(log), "--chain", str(chain), "--out", str(out), "--bootstrap", "5", "-q"]) == 0
    page = (out / "report.html").read_text()
    assert "latency at body_to_world" in page  # the verdict comes first
    # four figures, and the error against each fitted family's size (latency, mount rotation and translation, depth,
    # intrinsics)
    assert page.count("data:image/png;base64,") == 4 + 5
    assert "Median error against the pose latency" not in page  # in the PNG, not the page: its caption is
    assert "Pose latency: the error against the logged hops" in page
    assert "http://" not in page
    assert "https://" not in page
    assert "<script" not in page


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed")
def test_report_renders_in_headless_chromium(latency_log: tuple[Path, Path], tmp_path: Path) -> None:
    log, chain = latency_log
    out = tmp_path / "report"
    assert main(["report", str(log), "--chain", str(chain), "--out", str(out), "--bootstrap", "0", "-q"]) == 0
    png = tmp_path / "page.png"
    assert CHROMIUM is not None
    subprocess.run(
        [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         f"--user-data-dir={tmp_path / 'profile'}", "--hide-scrollbars", "--window-size=1200,2400",
         f"--screenshot={png}", (out / "report.html").as_uri()],
        check=True, capture_output=True, timeout=120,
    )
    import matplotlib.image

    image = matplotlib.image.imread(png)
    assert image.shape[0] == 2400
    assert image.shape[1] == 1200
    # The embedded plots rendered: the page is not blank white, and it has the plots' colours.
    rgb = image[..., :3]
    assert (rgb < 0.95).mean() > 0.05
    blue = (rgb[..., 2] > 0.6) & (rgb[..., 0] < 0.3)
    assert blue.sum() > 200


def test_demo_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--json", "--seed", "3"]) == 0
    doc = json.loads(capsys.readouterr().out)
    found = {f["fault"]: f["estimate"] for f in doc["findings"]}
    assert found["missing_rotation"]["angle_deg"] == pytest.approx(30.0, abs=0.5)
    assert found["latency"]["offset_s"] == pytest.approx(-0.03, abs=0.002)
    assert doc["findings"][0]["fault"] == "missing_rotation"  # sorted by share
    for name in ("episode.mcap", "chain.yaml", "attribution.json", "evidence.parquet", "report.html", "report.md",
                 "episode.rrd"):
        assert (out / name).exists(), name
    assert np.isclose(sum(f["share"] for f in doc["findings"]), 1.0, atol=0.05)


def test_demo_says_when_the_evidence_cannot_see_the_faults(tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--out", str(tmp_path / "d"), "--evidence", "static", "--no-rrd", "-q"]) == 0
    out, err = capsys.readouterr()
    assert "injected in the robot's computation, which --evidence static cannot see" in err
    assert "No fault beyond noise" in out  # right: the recording it is measured against is right
    assert "rerun" not in out.splitlines()[-1]  # no recording was written, none is offered


def test_unwritable_out_fails_before_the_analysis(latency_log: tuple[Path, Path], tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    log, chain = latency_log
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    assert main(["attribute", str(log), "--chain", str(chain), "--out", str(blocker / "out"), "-q"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert str(blocker) in err


@pytest.mark.parametrize("argv", [
    ["demo", "--fault", "wrong_world_frame@data"],
    ["demo", "--fault", "no_such_fault"],
])
def test_bad_demo_faults_are_one_line(argv: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*argv, "--out", str(tmp_path / "d")]) == 1
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_info_and_tf_take_quiet(latency_log: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    log, _ = latency_log
    assert main(["info", str(log), "--json", "-q"]) == 0
    assert json.loads(capsys.readouterr().out)["format"] == "mcap"
    assert main(["tf", str(log), "map", "base_link", "--csv", "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert out.startswith("stamp_ns,t_rel_s,x,y,z")
    assert err == ""


@pytest.mark.parametrize("at", ["nan", "inf", "1e20", "soon"])
def test_tf_bad_at_is_one_line(latency_log: tuple[Path, Path], at: str, capsys: pytest.CaptureFixture[str]) -> None:
    log, _ = latency_log
    assert main(["tf", str(log), "map", "base_link", "--at", at]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "--at" in err


def test_attribute_s_report_figures_are_drawn_by_its_renderers(latency_log: tuple[Path, Path], tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """The same report PNGs, drawn in the command's process and by renderer processes (the command's own
    drawing switched off, so that a figure drawn here would fail)."""
    from framechain.sinks import plots

    log, chain = latency_log
    argv = ["attribute", str(log), "--chain", str(chain), "--format", "md", "--bootstrap", "0", "-q"]
    monkeypatch.setenv(plots.RENDERERS_VARIABLE, "0")
    assert main([*argv, "--out", str(tmp_path / "here")]) == 0

    def not_here(sketch: object) -> bytes:
        raise AssertionError("drawn in the command's process")

    monkeypatch.setattr(plots, "render_png", not_here)
    monkeypatch.setenv(plots.RENDERERS_VARIABLE, "2")
    assert main([*argv, "--out", str(tmp_path / "drawn")]) == 0
    plots_here = sorted(p.name for p in (tmp_path / "here").glob("*.png") if not p.name.startswith("camera_"))
    assert {"error_per_hop.png", "world_top_down.png"} <= set(plots_here)
    for name in plots_here:
        assert (tmp_path / "drawn" / name).read_bytes() == (tmp_path / "here" / name).read_bytes(), name


@pytest.mark.parametrize("fails", [False, True])
def test_attribute_sets_its_imports_aside_from_the_collector_while_it_runs(
        latency_log: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, fails: bool) -> None:
    """While the log is read the objects already imported are frozen (gc.freeze); after the command, failed
    or not, the collector has them back (a test process runs many commands)."""
    import gc

    from framechain import pipeline
    from framechain.errors import FramechainError

    log, chain = latency_log
    run = pipeline.run
    frozen_during: list[int] = []

    def counting(*args: object, **kwargs: object) -> object:
        frozen_during.append(gc.get_freeze_count())
        if fails:
            raise FramechainError("stopped here")
        return run(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(pipeline, "run", counting)
    before = gc.get_freeze_count()
    code = main(["attribute", str(log), "--chain", str(chain), "--format", "md", "--bootstrap", "0", "-q",
                 "--out", str(tmp_path / "out")])
    assert code == (1 if fails else 0)
    [during] = frozen_during
    assert during > before + 10_000  # the imports' objects, not a handful
    assert gc.get_freeze_count() == before


def test_the_console_script_exits_with_main_s_code_without_the_teardown(tmp_path: Path) -> None:
    """The exit code is main's, its last output and the libraries' exit functions are kept, and no object is freed
    on the way out (an object's finalizer stands for the teardown)."""
    import subprocess
    import sys

    program = ("import atexit, sys\n"
               "from framechain.cli import main as cli_main\n"
               "class Held:\n"
               "    def __del__(self): sys.stderr.write('torn down')\n"
               "held = Held()\n"
               f"atexit.register(lambda: open({str(tmp_path / 'atexit')!r}, 'w').write('ran'))\n"
               "def command():\n"
               "    sys.stdout.write('the last line, unflushed')\n"
               "    return 3\n"
               "cli_main.main = command\n"
               "cli_main.entry()\n")
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 3
    assert done.stdout == "the last line, unflushed"
    assert (tmp_path / "atexit").read_text() == "ran"
    assert "torn down" not in done.stderr
