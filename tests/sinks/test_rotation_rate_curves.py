"""A camera's rotation-rate curves are computed once, with the run, and drawn as they are: the Rerun series hold the
run's numbers, and the report's plot is made from the same arrays."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from framechain import pipeline
from framechain.analysis.run import Run
from framechain.sim.lerobot_video import VideoDatasetSpec, generate_video_dataset, write_robot_yaml


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> Run:
    root = tmp_path_factory.mktemp("curves")
    truth = generate_video_dataset(root / "dataset", VideoDatasetSpec(
        so101_urdf, seed=91, duration_s=3.0, version="v3.0", video_delay_s=0.060))
    robot = write_robot_yaml(truth, root / "robot.yaml")
    return pipeline.run(truth.root, episode=0, robot=robot, bootstrap=0)


def test_the_run_carries_each_cameras_curves(run: Run) -> None:
    assert len(run.rotation_rates) == 1
    curves = run.rotation_rates[0]
    assert curves.camera == "wrist_optical_frame"
    assert np.all(np.diff(curves.middle_ns) > 0)  # neighbouring frames, in time order
    for series in (curves.measured, curves.declared, curves.fitted):
        assert series.components_deg_s.shape == (curves.middle_ns.size, 3)
        np.testing.assert_array_equal(series.magnitude_deg_s, np.linalg.norm(series.components_deg_s, axis=1))


def test_rerun_draws_the_runs_numbers(run: Run, tmp_path: Path) -> None:
    import rerun as rr
    from rerun.chunk import RrdReader

    from framechain.sinks.rerun import log_replay

    rec = rr.RecordingStream("framechain-test", recording_id="curves")
    memory = rec.memory_recording()
    log_replay(rec, run)
    rec.flush()
    path = tmp_path / "curves.rrd"
    path.write_bytes(memory.drain_as_bytes())
    curves = run.rotation_rates[0]
    for leaf, values in (("measured", curves.measured.magnitude_deg_s), ("corrected", curves.fitted.magnitude_deg_s),
                         ("x/declared", curves.declared.components_deg_s[:, 0])):
        stored = [v[0] for chunk in RrdReader(path).stream()
                  if chunk.entity_path == f"/series/rotation_rate_deg_s/wrist/{leaf}" and not chunk.is_static
                  for v in chunk.to_record_batch().column("Scalars:scalars").to_pylist()]
        np.testing.assert_array_equal(stored, values[np.isfinite(values)])


def test_the_report_plots_the_runs_numbers(run: Run, monkeypatch: pytest.MonkeyPatch) -> None:
    from framechain.sinks import report_figures

    drawn: list[Any] = []
    monkeypatch.setattr(report_figures, "figure_png", lambda fig, name, caption: drawn.append((name, fig.sketch)))
    report_figures.motion_figures(run)
    curves = run.rotation_rates[0]
    ((name, sketch),) = drawn
    assert name == "rotation_rate_wrist_optical_frame"
    lines = [args for _target, method, args, _kwargs in sketch.calls if method == "plot"]
    for (t, y), series in zip(lines, (curves.measured, curves.declared, curves.fitted), strict=True):
        np.testing.assert_array_equal(t, curves.middle_ns * 1e-9)
        assert y is series.magnitude_deg_s
