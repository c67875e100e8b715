"""One text per finding: the typed estimates, their one formatter, JSON and scalars."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from rerun.chunk import RrdReader

from framechain.analysis.model.estimates import (
    Estimate,
    FrameEstimate,
    InvertedEstimate,
    LatencyEstimate,
    PermutationEstimate,
    RotationEstimate,
    ScaleEstimate,
    estimate_scalars,
    estimate_to_json,
    format_estimate,
    format_interval,
)
from framechain.catalogue import Fault
from framechain.cli.common import print_findings
from framechain.pipeline import run
from framechain.sim.scene import InjectedFault, SceneSpec, generate
from framechain.sinks.evidence_files import write_attribution
from framechain.sinks.report import render_report
from framechain.sinks.rerun import RerunTarget, stream_replay

CASES: list[tuple[Estimate, str, dict[str, object], dict[str, float]]] = [
    (LatencyEstimate(offset_s=-0.0312), "-31.2 ms", {"offset_s": -0.0312}, {"offset_s": -0.0312}),
    (LatencyEstimate(offset_s=0.005), "+5.0 ms", {"offset_s": 0.005}, {"offset_s": 0.005}),
    (RotationEstimate(angle_deg=2.0, axis=(0.0, -1.0, 0.0), axis_frame="camera_link", faulty="recorded data"),
     "2.00 deg about -y of camera_link",
     {"angle_deg": 2.0, "axis": [0.0, -1.0, 0.0], "axis_frame": "camera_link", "faulty": "recorded data"},
     {"angle_deg": 2.0}),
    (RotationEstimate(angle_deg=4.5, axis=(0.6, 0.0, 0.8), axis_frame="wrist_link", faulty="as run"),
     "4.50 deg about [0.6, 0.0, 0.8] of wrist_link",
     {"angle_deg": 4.5, "axis": [0.6, 0.0, 0.8], "axis_frame": "wrist_link", "faulty": "as run"},
     {"angle_deg": 4.5}),
    (ScaleEstimate(name="factor", value=1.05), "x1.05", {"factor": 1.05}, {"factor": 1.05}),
    (ScaleEstimate(name="factor", value=1000.0), "x1000", {"factor": 1000.0}, {"factor": 1000.0}),
    (ScaleEstimate(name="scale", value=2.0, variant="resolution"), "x2, K of another resolution",
     {"scale": 2.0, "variant": "resolution"}, {"scale": 2.0}),
    (ScaleEstimate(name="scale", value=1.25, variant="focal"), "x1.25, focal length of another lens",
     {"scale": 1.25, "variant": "focal"}, {"scale": 1.25}),
    (PermutationEstimate(permutation=((0, 0, 1), (-1, 0, 0), (0, -1, 0))), "axes [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]",
     {"permutation": [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]}, {}),
    (FrameEstimate(used="camera_link", meant="camera_color_optical_frame", hop="camera_to_body"),
     "looked up camera_link instead of camera_color_optical_frame",
     {"used": "camera_link", "meant": "camera_color_optical_frame", "hop": "camera_to_body"}, {}),
    (FrameEstimate(used="odom", meant="map", hop="body_to_world", skipped=(("map", "odom"),)),
     "looked up odom instead of map, skipping map->odom",
     {"used": "odom", "meant": "map", "hop": "body_to_world", "skipped": [["map", "odom"]]}, {}),
    (InvertedEstimate(hop="camera_to_body", edge=("base_link", "camera_link")),
     "camera_to_body inverted at edge base_link->camera_link",
     {"hop": "camera_to_body", "edge": ["base_link", "camera_link"]}, {}),
    (InvertedEstimate(hop="body_to_world"), "body_to_world inverted", {"hop": "body_to_world"}, {}),
]


@pytest.mark.parametrize(("estimate", "text", "as_json", "scalars"), CASES)
def test_one_text_json_and_scalars_per_estimate(
    estimate: Estimate, text: str, as_json: dict[str, object], scalars: dict[str, float]
) -> None:
    assert format_estimate(estimate) == text
    assert estimate_to_json(estimate) == as_json
    assert json.loads(json.dumps(estimate_to_json(estimate))) == as_json  # plain JSON types only
    assert estimate_scalars(estimate) == scalars


@pytest.mark.parametrize("estimate", [case[0] for case in CASES])
def test_estimate_text_reads_inside_the_verdicts_parentheses(estimate: Estimate) -> None:
    """The verdict and evidence sentences put the text in parentheses: it must hold none of its own."""
    text = format_estimate(estimate)
    assert "(" not in text
    assert ")" not in text


def test_interval_text() -> None:
    assert format_interval({"offset_s": [-0.0315, -0.0309]}) == "-31.50 .. -30.90 ms"
    assert format_interval({"angle_deg": [1.9, 2.1]}) == "1.900 .. 2.100 deg"
    assert format_interval({"factor": [1.049, 1.051]}) == "x1.049 .. x1.051"
    assert format_interval({}) == "-"


def test_every_output_shows_the_same_estimate_text(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scene = generate(SceneSpec(seed=3, duration_s=4.0, evidence="hops",
                               faults=(InjectedFault(Fault.LATENCY, params={"offset_s": -0.03}),)))
    made = run(scene.timeline, scene.chain, bootstrap=0)
    result = made.attributed()
    top = result.findings[0]
    assert top.fault == Fault.LATENCY
    text = format_estimate(top.estimate)
    assert re.fullmatch(r"-(29\.[5-9]|30\.[0-5]) ms", text), text  # the injected -30 ms, to 0.5 ms
    assert f"({text})" in result.verdict
    assert f"({text})" in top.evidence
    print_findings(result)
    assert text in capsys.readouterr().out
    report = render_report(made, tmp_path, formats=("md",))["md"].read_text()
    assert f"| {text} |" in report
    rrd = tmp_path / "finding.rrd"
    stream_replay(made, RerunTarget.save(rrd))
    logged = [row[0] for chunk in RrdReader(rrd).stream() if chunk.entity_path == "/log/findings"
              for row in chunk.to_record_batch().column("TextLog:text").to_pylist()]
    assert logged
    assert f"estimate {text}" in logged[0]
    saved = json.loads(write_attribution(made, tmp_path)["attribution"].read_text())
    assert saved["findings"][0]["estimate"] == {"offset_s": pytest.approx(-0.03, abs=5e-4)}
