"""Every output says what a log could check: the bounds and the labels in the CLI, both reports and the Rerun
recording, the curves as report figures and as Rerun bar charts and series."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from rerun.chunk import RrdReader

from framechain import pipeline
from framechain.analysis.run import Run
from framechain.catalogue import Fault
from framechain.cli.main import main
from framechain.sim import InjectedFault, SceneSpec, generate, write_scene
from framechain.sinks.report import render_report
from framechain.sinks.rerun import RerunTarget, stream_replay
from framechain.sinks.rerun_checks import OFFSET_TIMELINE


@pytest.fixture(scope="module")
def latency_run() -> Run:
    scene = generate(SceneSpec(seed=6, duration_s=5.0, evidence="static",
                               faults=(InjectedFault(Fault.LATENCY, "data", {"offset_s": 0.030}),)))
    return pipeline.run(scene.timeline, scene.chain, bootstrap=0)


def test_the_recording_holds_the_checks_and_the_curves(latency_run: Run, tmp_path: Path) -> None:
    rrd = tmp_path / "run.rrd"
    stream_replay(latency_run, RerunTarget.save(rrd))
    chunks: dict[str, list[Any]] = defaultdict(list)
    for chunk in RrdReader(rrd).stream():
        chunks[chunk.entity_path].append(chunk)
    (doc,) = [c.to_record_batch() for c in chunks["/checks"]]
    text = doc.column("TextDocument:text").to_pylist()[0][0]
    assert "# What this log can show" in text
    assert latency_run.attributed().verdict in text
    assert "| mount rotation | camera_to_body |" in text
    bars = [c.to_record_batch() for c in chunks["/curves/latency_body_to_world/error"]]
    assert bars
    assert all(c.is_static for c in chunks["/curves/latency_body_to_world/error"])
    curve = next(c for c in latency_run.attributed().curves if c.fault == Fault.LATENCY)
    abscissa = np.asarray(bars[0].column("BarChart:abscissa").to_pylist()[0][0]["buffer"], dtype=float)
    # The bars zoom on the estimate (ms): four bounds or 20 ms either side, of the whole second searched.
    half = max(4.0 * (curve.bound or 0.0), 0.020) * 1e3
    assert abscissa.min() >= curve.estimate * 1e3 - half - 1e-6
    assert abscissa.max() <= curve.estimate * 1e3 + half + 1e-6
    assert abscissa.max() - abscissa.min() > half
    assert "/curves/latency_body_to_world/estimate" in chunks
    assert "/curves/latency_body_to_world/bound_high" in chunks
    series = chunks["/curves/latency_body_to_world/series"]
    assert series
    assert OFFSET_TIMELINE in series[0].timeline_names
    assert len(series[0].to_record_batch()) == len(curve.x)
    for fault in ("rotation_error_camera_to_body", "depth_scale_pixel_to_camera", "intrinsics_pixel_to_camera"):
        assert f"/curves/{fault}/error" in chunks


def test_the_reports_show_the_bounds_curves_and_labels(latency_run: Run, tmp_path: Path) -> None:
    paths = render_report(latency_run, tmp_path)
    page = paths["html"].read_text()
    md = paths["md"].read_text()
    for text in (page, md):
        assert "What this log can show" in text
        assert "Per label" in text
        assert "smallest fault it would find" in text
        assert text.index("What this log can show") < text.index("Provenance")
    assert "strength" in md.split("## Error")[0]  # the findings table says strong or weak
    assert (tmp_path / "curve_latency_body_to_world.png").is_file()
    assert "![Pose latency: the error against the static spread" in md


def test_the_cli_says_a_fixed_camera_could_check_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = generate(SceneSpec(seed=4, duration_s=4.0, evidence="static", fixed_camera=True))
    log = write_scene(scene, tmp_path / "fixed.mcap")
    chain = tmp_path / "chain.yaml"
    chain.write_text(yaml.safe_dump(scene.chain.to_dict()))
    assert main(["attribute", str(log), "--chain", str(chain), "--out", str(tmp_path / "out"), "--bootstrap", "0",
                 "-q"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("Nothing could be checked")
    assert "not observable" in out  # the bounds table
    doc = yaml.safe_load((tmp_path / "out" / "attribution.json").read_text())
    assert {b["fault"]: b["observable"] for b in doc["bounds"]} == {
        "latency": False, "rotation_error": False, "translation_error": False, "depth_scale": False,
        "intrinsics": False}
    page = (tmp_path / "out" / "report.html").read_text()
    assert "class='verdict'" in page  # not the green "clean" box: nothing could be checked


def test_a_rig_s_bounds_per_camera_and_a_run_without_bounds_say_so_in_every_output(tmp_path: Path) -> None:
    """A rig measured against its other cameras: each camera's bounds in the verdict, both reports and the Rerun
    document; the same run with no bound computed says that the smallest fault it would have shown is not known."""
    import dataclasses

    from framechain.sim.rig import RigSpec, generate_rig
    from framechain.sinks.checks_view import NOT_BOUNDED
    from framechain.sinks.rerun_checks import checks_markdown

    scene = generate_rig(RigSpec(cameras=3, duration_s=4.0, rate_hz=15.0, static_tags=8, seed=3, pose="fixed"))
    run = pipeline.run(scene.timeline, scene.chain, bootstrap=0)
    result = run.attributed()
    doc = result.to_json()
    assert doc["error_m"]["metric"] == "cross_camera"
    cameras = {b["camera"] for b in doc["bounds"]}
    assert cameras == {scene.frame(k) for k in range(3)}
    assert doc["verdict"].startswith("No fault beyond noise")
    assert "Not bounded" not in doc["verdict"]
    paths = render_report(run, tmp_path)
    for text in (paths["md"].read_text(), paths["html"].read_text(), checks_markdown(result)):
        for camera in cameras:
            assert f"on camera {camera}" in text
        assert NOT_BOUNDED not in text
    unbounded = dataclasses.replace(result, bounds=())
    assert "Not bounded: the smallest fault this log would have shown was not computed for evidence from the other " \
           "cameras of the rig" in unbounded.verdict
    assert NOT_BOUNDED in checks_markdown(unbounded)
