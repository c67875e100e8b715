"""Each figure of the reports shows what its caption says, or is not drawn; its colours are the palette's (the
legend's), never red for an error a finding explains; the bounds' axis and the plot's are the same.

The figures are read as the matplotlib calls recorded on them (:class:`framechain.sinks.plots.Sketch`), before
any drawing.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import pytest

from framechain import pipeline
from framechain.catalogue import Fault
from framechain.sim import InjectedFault, SceneSpec, generate
from framechain.sim.rig import RigSpec, generate_rig
from framechain.sinks import fleet_report, report_figures
from framechain.sinks.colors import (
    BOUND_COLOR,
    ERROR_COLOR,
    FAULT_COLORS,
    RECORDED_ERROR_COLOR,
    hex_color,
)
from framechain.sinks.document import markdown
from framechain.sinks.plots import Figure

Sketches = dict[str, tuple[str, Any]]


def _capture(monkeypatch: pytest.MonkeyPatch, module: Any) -> Sketches:
    """Each figure the module makes, by name: its caption and recorded sketch (drawn by nobody)."""
    made: Sketches = {}

    def keep(fig: Any, name: str, caption: str) -> Figure:
        made[name] = (caption, fig.sketch)
        return Figure(name, caption, b"")

    monkeypatch.setattr(module, "figure_png", keep)
    return made


def _calls(sketch: Any, method: str) -> list[tuple[tuple[Any, ...], dict[str, Any]]]:
    return [(args, kwargs) for _target, name, args, kwargs in sketch.calls if name == method]


def _colours(sketch: Any) -> set[str]:
    return {kwargs["color"] for _t, _n, _a, kwargs in sketch.calls if isinstance(kwargs.get("color"), str)}


def test_a_static_target_draws_one_error_over_time_never_red(monkeypatch: pytest.MonkeyPatch) -> None:
    """Static targets log no hop: the figure is the error over time (not "per hop"), as recorded in the palette's
    grey, after the findings in purple; the sensitivity of the top finding is drawn against the chain's tolerance,
    in the fault's colour, and no "gripper tolerance" a hand-held rig does not have."""
    scene = generate(SceneSpec(seed=6, duration_s=5.0, evidence="static",
                               faults=(InjectedFault(Fault.LATENCY, "data", {"offset_s": 0.030}),)))
    run = pipeline.run(scene.timeline, replace(scene.chain, tolerance_m=0.002), bootstrap=0)
    made = _capture(monkeypatch, report_figures)
    report_figures.make_figures(run.attributed())
    caption, over_time = made["error_per_hop"]
    assert caption.startswith("Error against the static spread over time (no hop logged")
    assert hex_color(ERROR_COLOR) not in _colours(over_time)
    assert hex_color(RECORDED_ERROR_COLOR) in _colours(over_time)
    assert len(_calls(over_time, "plot")) == 2  # as recorded, and after the findings: no hop lines
    _, speed = made["error_vs_speed"]
    dots = [kwargs for _args, kwargs in _calls(speed, "plot") if kwargs.get("label") == "as recorded"]
    assert dots[0]["color"] == hex_color(RECORDED_ERROR_COLOR)
    _, sensitivity = made["sensitivity"]
    (tolerance,) = _calls(sensitivity, "axhline")
    assert tolerance[0] == (pytest.approx(2.0),)  # 2 mm, the chain's
    assert tolerance[1]["label"] == "the 2 mm tolerance (tolerance_m)"
    assert tolerance[1]["color"] == hex_color(BOUND_COLOR)
    assert "gripper" not in repr(sensitivity.calls)
    line = _calls(sensitivity, "plot")[0][1]
    assert line["color"] == hex_color(FAULT_COLORS["latency"])


def test_a_rig_with_no_pose_draws_no_error_against_speed(monkeypatch: pytest.MonkeyPatch) -> None:
    scene = generate_rig(RigSpec(cameras=3, duration_s=3.0, rate_hz=15.0, static_tags=12, seed=3, pose="none"))
    run = pipeline.run(scene.timeline, scene.chain, bootstrap=0)
    made = _capture(monkeypatch, report_figures)
    report_figures.make_figures(run.attributed())
    assert "error_vs_speed" not in made  # every point would sit at 0 m/s
    assert "error_per_hop" in made


def test_fleet_counts_are_whole_and_one_log_is_one_log(monkeypatch: pytest.MonkeyPatch) -> None:
    logs = [fleet_report.FleetLog(unit="a.bag", log="a.bag", status="findings", error=None, verdict="v",
                                  error_median_m=0.01,
                                  findings=[{"fault": "latency", "hop": "body_to_world", "estimate_name": "offset_s",
                                             "estimate_value": 0.03, "actionable": True}])]
    made = _capture(monkeypatch, fleet_report)
    fleet_report.make_fleet_figures(logs)
    _, bars = made["fleet_faults"]
    whole = [kwargs for _args, kwargs in _calls(bars, "locator_params") if kwargs == {"axis": "x", "integer": True}]
    assert len(whole) == 2
    _, estimates = made["fleet_estimates"]
    (title,) = _calls(estimates, "set_title")
    assert title[0][0] == "latency at body_to_world (1 log)"
    assert fleet_report.summary_line(logs).startswith("1 log: ")


def test_which_logs_orders_by_error_within_each_unit() -> None:
    """A camera-motion episode's 97 deg/s is not larger than a bag's 0.2 m: logs measured in metres are listed
    first, largest first, then the camera-motion ones, largest first."""
    def log(unit: str, error: float, metric: str | None) -> fleet_report.FleetLog:
        finding = {"fault": "latency", "hop": "camera_to_body", "estimate_text": "30 ms", "share": 0.5}
        return fleet_report.FleetLog(unit=unit, log=unit, status="findings", error=None, verdict="v",
                                     error_median_m=error, findings=[finding], metric=metric)

    logs = [log("episode_small", 3.0, "camera_motion"), log("a.bag", 0.05, None),
            log("episode_large", 97.0, "camera_motion"), log("b.bag", 0.2, None)]
    text = markdown(fleet_report.fleet_document(logs, [], []))
    which = text.split("## Which logs have which fault", 1)[1]
    rows = [line.split("|")[1].strip() for line in which.splitlines()
            if line.startswith(("| a.bag", "| b.bag", "| episode"))]
    assert rows == ["b.bag", "a.bag", "episode_large", "episode_small"]
    assert "200.0 mm" in which
    assert "97.00 deg/s" in which
