"""A camera's rotation-rate curves are computed once, with the run, and drawn as they are: the Rerun series hold the
run's numbers, and the report's plot is made from the same arrays."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

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


def drawn_lines(run: Run, monkeypatch: pytest.MonkeyPatch) -> dict[str, list[tuple[Any, ...]]]:
    """The report's motion figures as sketched: each figure's name, and the (x, y) of every line drawn in it."""
    from framechain.sinks import report_figures

    drawn: dict[str, list[tuple[Any, ...]]] = {}
    monkeypatch.setattr(report_figures, "figure_png", lambda fig, name, caption: drawn.setdefault(name, [
        args for _target, method, args, _kwargs in fig.sketch.calls if method == "plot"]))
    report_figures.motion_figures(run)
    return drawn


def test_the_report_plots_the_runs_numbers(run: Run, monkeypatch: pytest.MonkeyPatch) -> None:
    drawn = drawn_lines(run, monkeypatch)
    curves = run.rotation_rates[0]
    assert list(drawn) == ["rotation_rate_wrist_optical_frame", "rotation_misfit_wrist_optical_frame"]
    for (t, y), series in zip(drawn["rotation_rate_wrist_optical_frame"],
                              (curves.measured, curves.declared, curves.fitted), strict=True):
        np.testing.assert_array_equal(t, curves.middle_ns * 1e-9)
        assert y is series.magnitude_deg_s
    for (t, y), series in zip(drawn["rotation_misfit_wrist_optical_frame"], (curves.declared, curves.fitted),
                              strict=True):
        np.testing.assert_array_equal(t, curves.middle_ns * 1e-9)
        np.testing.assert_allclose(y, [np.linalg.norm(m - p) for m, p in zip(
            curves.measured.components_deg_s, series.components_deg_s, strict=True)], rtol=1e-12)


def test_a_mount_error_shows_in_the_misfit_not_in_the_rates_size(tmp_path: Path, so101_urdf: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """Mounted 20 deg off what robot.yaml declares, on time: the rate's size agrees as declared; its components miss
    by (I - R) w, R the declared mount's turn against the true one (scipy), until the fitted mount takes it away."""
    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(
        so101_urdf, seed=92, duration_s=3.0, version="v3.0", mount_error_deg=20.0))
    run = pipeline.run(truth.root, episode=0, robot=write_robot_yaml(truth, tmp_path / "robot.yaml"), bootstrap=0)
    curves = run.rotation_rates[0]
    measured = curves.measured.components_deg_s
    (_, size), (_, declared_size), _fitted = drawn_lines(run, monkeypatch)["rotation_rate_wrist_optical_frame"]
    (_, before), (_, after) = drawn_lines(run, monkeypatch)["rotation_misfit_wrist_optical_frame"]
    turn = Rotation.from_quat(truth.declared_q_link_cam).inv() * Rotation.from_quat(truth.q_link_cam)
    expected = np.linalg.norm(measured - turn.apply(measured), axis=1)
    typical = float(np.median(size))
    assert np.median(np.abs(size - declared_size)) < 0.05 * typical
    assert np.median(before) > 0.15 * typical  # 2 sin(10 deg) = 0.35 of the rate across the axis
    assert np.median(np.abs(before - expected)) < 0.25 * np.median(before)
    assert np.nanmedian(after) < 0.25 * np.median(before)  # (none at an end the fitted offset moves past)
