"""One recording, one rig: a two-arm recording's cameras fitted across its episodes, against the generator's truth.

The generated recording has a wrist camera on each arm, swapped against robot.yaml (each declared on the
other arm), recorded as real recorders do (real-time stamps, MPEG-4 at 224x224, a wide lens, resent
frames), each camera late by its own delay, and one episode 100 ms later on top. Truth: which arm
carries which camera, the true mount, the delays injected.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

from framechain.cli.main import main
from framechain.fleet import BatchResult, run_batch
from framechain.sim.lerobot_video import VideoDatasetSpec, VideoDatasetTruth, generate_video_dataset, write_robot_yaml

EPISODES = 5
LATE_EPISODE = 3


@pytest.fixture(scope="module")
def swapped(tmp_path_factory: pytest.TempPathFactory, so101_urdf: Path) -> tuple[VideoDatasetTruth, Path, BatchResult]:
    folder = tmp_path_factory.mktemp("recording")
    delays = tuple(0.1 if e == LATE_EPISODE else 0.0 for e in range(EPISODES))
    spec = VideoDatasetSpec(so101_urdf, seed=7, episodes=EPISODES, duration_s=6.0, fps=20, codec="mpeg4", bimanual=True,
                            camera_per_arm=True, swap_cameras=True, clock="realtime", focal_px=112.0,
                            repeat_share=0.15, camera_delays_s=(0.06, 0.09), episode_delays_s=delays)
    truth = generate_video_dataset(folder / "dataset", spec)
    robot = write_robot_yaml(truth, folder / "robot.yaml")
    return truth, robot, run_batch([truth.root], folder / "out", robot=robot, jobs=1, report_formats=("md",),
                                   rrd=folder / "out" / "recording.rrd")


def test_the_recording_names_the_swap_for_both_cameras(swapped: tuple[VideoDatasetTruth, Path, BatchResult]) -> None:
    truth, _robot, result = swapped
    (fits,) = result.recordings.values()
    by_camera = {fit.name: fit for fit in fits}
    for camera in truth.cameras:
        fit = by_camera[camera.name]
        assert fit.declared_link == camera.declared_link != camera.camera_link
        assert fit.link == camera.camera_link
        measured = Rotation.from_quat(fit.q_link_cam)
        assert np.rad2deg((measured.inv() * Rotation.from_quat(camera.q_link_cam)).magnitude()) < 3.0
        # Each episode's own mount agrees with the recording's.
        assert max(fit.episode_mount_deg.values()) < 2.0
        assert len(fit.episode_mount_deg) == EPISODES


def test_every_episodes_offset_is_in_the_camera_table_and_the_late_one_departs(
        swapped: tuple[VideoDatasetTruth, Path, BatchResult]) -> None:
    truth, _robot, result = swapped
    rows = pq.read_table(result.report_paths["cameras"]).to_pylist()
    assert len(rows) == EPISODES * len(truth.cameras)
    for camera in truth.cameras:
        mine = sorted((r for r in rows if r["name"] == camera.name), key=lambda r: r["episode"])
        for row, delay in zip(mine, camera.delays_s, strict=True):
            assert row["offset_s"] == pytest.approx(-delay, abs=0.005)  # within 1.6 ms measured
            assert row["offset_low_s"] < row["offset_s"] < row["offset_high_s"]
            assert row["link"] == row["recording_link"] == camera.camera_link
            assert row["mount_from_recording_deg"] < 2.0  # each episode's mount agrees with the recording's
        assert [r["episode"] for r in mine if r["departs"]] == [LATE_EPISODE]
        (late,) = [r for r in mine if r["departs"]]
        assert "departs from the recording's median" in late["why"]
    document = json.loads(result.report_paths["recording"].read_text())
    assert {c["name"] for c in document["recordings"][0]["cameras"]} == {c.name for c in truth.cameras}
    report = (result.table_path.parent / "fleet_report.md").read_text()
    assert "## Cameras across each recording's episodes" in report
    # Each camera's table: one row per episode, the late one departing and why, the others not.
    section = report.split("## Cameras across each recording's episodes", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if line.startswith("| ") and line[2].isdigit()]
    assert len(rows) == EPISODES * len(truth.cameras)
    for row in rows:
        late = row.startswith(f"| {LATE_EPISODE} |")
        assert ("departs from the recording's median" in row) == late, row
        assert row.rstrip().endswith("| no |") != late, row


def test_the_fleets_offsets_are_judged_per_camera(swapped: tuple[VideoDatasetTruth, Path, BatchResult],
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """Both cameras' offsets in every episode (60 and 90 ms late, one episode 100 ms more): each camera against its
    own median, the late episode disagreeing for both, and the fleet's plot of estimates one box per camera."""
    from framechain.sinks import fleet_report

    truth, robot, result = swapped
    report = (result.table_path.parent / "fleet_report.md").read_text()
    # Analysed with the robot.yaml given (not a "suggested" chain), as the table's chain column says.
    assert f"Chains: {robot} ({EPISODES} logs)." in report
    table = pq.read_table(result.table_path).to_pylist()
    assert {row["chain"] for row in table} == {str(robot)}
    # Each log's median error in its unit: deg/s of rotation rate (it read as metres, "97049.2 mm").
    which = report.split("## Which logs have which fault", 1)[1].split("\n## ", 1)[0]
    for row in table:
        (line,) = [ln for ln in which.splitlines() if ln.startswith(f"| {row['unit']} |")]
        assert f"| {row['error_median_m']:.2f} deg/s |" in line
        assert " mm |" not in line
    section = report.split("## Video/state time offset per log", 1)[1].split("\n## ", 1)[0]
    for camera in truth.cameras:
        frame = f"{camera.name}_optical_frame"
        median = np.median([-d for d in camera.delays_s]) * 1e3
        (summary,) = [line for line in section.splitlines() if line.startswith(f"Camera {frame}, ")]
        assert f"Camera {frame}, {EPISODES} logs: median " in summary
        assert float(summary.split("median ")[1].split(" ms")[0]) == pytest.approx(median, abs=3.0)
        assert summary.endswith(f"disagree: {truth.root.resolve()} episode {LATE_EPISODE}.")
        rows = [line for line in section.splitlines() if f"| {frame} |" in line]
        assert len(rows) == EPISODES
        assert [r.rstrip(" |").endswith("no") for r in rows] == [e == LATE_EPISODE for e in range(EPISODES)]
    drawn: list[str] = []
    monkeypatch.setattr(fleet_report, "figure_png", lambda fig, name, caption: drawn.extend(
        args[0] for _t, method, args, _k in fig.sketch.calls if method == "set_title" and name == "fleet_estimates"))
    fleet_report.make_fleet_figures(fleet_report.fleet_logs(pq.read_table(result.table_path)))
    boxes = sorted(title.split(" (")[0] for title in drawn)
    assert boxes == sorted(f"latency on {c.name}_optical_frame" for c in truth.cameras)


def test_attribute_episodes_prints_the_recording(swapped: tuple[VideoDatasetTruth, Path, BatchResult],
                                                 tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """attribute DATASET --episodes reuses the batch's results (resumed: nothing measured again) and says per camera
    which link it rides and which episodes depart."""
    truth, robot, result = swapped
    out = result.table_path.parent
    assert main(["attribute", str(truth.root), "--robot", str(robot), "--episodes", "all", "--out", str(out),
                 "--format", "md", "-j", "1"]) == 0
    said = " ".join(capsys.readouterr().out.split())
    assert f"{EPISODES} episodes:" in said
    for camera in truth.cameras:
        assert f"camera {camera.name}_optical_frame: rides {camera.camera_link} (declared on {camera.declared_link})" \
            in said
    assert f"episode {LATE_EPISODE}: its offset" in said


def _series(path: Path, entity: str) -> dict[int, float]:
    """A scalar series of a saved recording, by episode (read back with rerun.chunk)."""
    from rerun.chunk import RrdReader

    out: dict[int, float] = {}
    for chunk in RrdReader(path).stream().filter(content=entity, components="Scalars:scalars"):
        batch = chunk.to_record_batch()
        for episode, value in zip(batch.column("episode").to_pylist(), batch.column("Scalars:scalars").to_pylist(),
                                  strict=True):
            out[int(episode)] = float(value[0])
    return out


def test_the_recording_view_shows_each_cameras_offsets_and_reaches_every_episode(
        swapped: tuple[VideoDatasetTruth, Path, BatchResult]) -> None:
    from rerun.chunk import RrdReader

    truth, _robot, result = swapped
    path = result.report_paths["rrd"]
    rows = pq.read_table(result.report_paths["cameras"]).to_pylist()
    for camera in truth.cameras:
        frame = f"{camera.name}_optical_frame"
        offsets = _series(path, f"/recording/{frame}/offset_ms/offset")
        expected = {r["episode"]: r["offset_s"] * 1e3 for r in rows if r["name"] == camera.name}
        assert offsets == pytest.approx(expected, abs=1e-3)
        low = _series(path, f"/recording/{frame}/offset_ms/low")
        assert all(low[e] < offsets[e] for e in offsets)
        assert set(_series(path, f"/recording/{frame}/mount_deg")) == set(range(EPISODES))
        warnings = [line for chunk in RrdReader(path).stream().filter(content=f"/recording/{frame}/departs",
                                                                      components="TextLog:text")
                    for line in chunk.to_record_batch().column("TextLog:text").to_pylist()]
        assert len(warnings) == 1
        assert warnings[0][0].startswith(f"episode {LATE_EPISODE}: its offset")
    episodes = sorted(path.with_name(f"{path.name}.episodes").glob("*.rrd"))
    assert len(episodes) == EPISODES
    ids = {str(r) for e in episodes for r in RrdReader(e).recordings()}
    assert len(ids) == EPISODES


def test_an_episode_that_measured_nothing_of_a_camera_is_left_out_with_why(tmp_path: Path, so101_urdf: Path) -> None:
    """Three episodes, one file per episode and camera (v2.1); the left camera's video of episode 1 is gone. The
    recording's fit of that camera rests on episodes 0 and 2 and says episode 1 is left out, naming the file, in its
    sentence, its table rows (one per episode and camera: 6) and recording.json; the right camera keeps all three."""
    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(
        so101_urdf, seed=7, episodes=3, duration_s=4.0, version="v2.1", bimanual=True, camera_per_arm=True))
    robot = write_robot_yaml(truth, tmp_path / "robot.yaml")
    (gone,) = list((truth.root / "videos").rglob("observation.images.left_wrist/episode_000001.mp4"))
    gone.unlink()
    result = run_batch([truth.root], tmp_path / "out", robot=robot, jobs=1, bootstrap=0, report_formats=("md",))
    fits = {fit.name: fit for fit in result.recordings[str(truth.root.resolve())]}
    assert [e.episode for e in fits["left_wrist"].episodes] == [0, 2]
    ((episode, why),) = fits["left_wrist"].left_out
    assert episode == 1
    assert "episode_000001.mp4" in why
    assert [e.episode for e in fits["right_wrist"].episodes] == [0, 1, 2]
    assert fits["right_wrist"].left_out == ()
    rows = pq.read_table(result.report_paths["cameras"]).to_pylist()
    assert sorted((r["name"], r["episode"]) for r in rows) == [(n, e) for n in ("left_wrist", "right_wrist")
                                                              for e in range(3)]
    (left_row,) = [r for r in rows if r["name"] == "left_wrist" and r["episode"] == 1]
    assert left_row["offset_s"] is None
    assert left_row["why"].startswith("left out: ")
    assert not left_row["departs"]
    report = (result.table_path.parent / "fleet_report.md").read_text()
    (sentence,) = [line for line in report.splitlines() if "camera left_wrist_optical_frame: rides" in line]
    assert "in the fit of 2 episode(s)" in sentence
    assert "; left out: episode 1 (" in sentence
    assert "episode_000001.mp4" in sentence
    document = json.loads(result.report_paths["recording"].read_text())
    (left,) = [c for c in document["recordings"][0]["cameras"] if c["name"] == "left_wrist"]
    assert [item["episode"] for item in left["left_out"]] == [1]


def test_a_camera_the_model_explains_in_no_episode_claims_nothing(
        swapped: tuple[VideoDatasetTruth, Path, BatchResult]) -> None:
    """No explained episode: the sentence claims no link, mount or offset (no "median offset +nan ms")."""
    from dataclasses import replace

    from framechain.sinks.fleet_cameras import camera_summary

    _truth, _robot, result = swapped
    ((log, fits),) = result.recordings.items()
    unexplained = replace(fits[0], episodes=tuple(replace(e, explained=False) for e in fits[0].episodes))
    sentence = camera_summary(log, unexplained)
    assert sentence == (f"{log}, camera {fits[0].camera}: the model explains its motion in none of the {EPISODES} "
                        "episode(s) measured: no link, mount or offset for the recording.")
    document = json.loads(json.dumps(unexplained.to_json(), allow_nan=False))  # valid JSON: no NaN
    assert (document["link"], document["q_link_cam"], document["median_offset_s"]) == (None, None, None)


def test_an_episode_too_short_to_show_anything_is_left_out_of_the_recording(tmp_path: Path, so101_urdf: Path) -> None:
    """Two 3 s episodes, the offset searched +-0.8 s: each compares 1.3 s of frame pairs, too short to show anything.
    Their fits still carry a link and an offset; the recording takes neither, and says why each is left out."""
    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(
        so101_urdf, seed=5, episodes=2, duration_s=3.0, version="v2.1"))
    robot = write_robot_yaml(truth, tmp_path / "robot.yaml")
    robot.write_text(robot.read_text() + "chain: {evidence: {camera_offset_window_s: 0.8}}\n")
    result = run_batch([truth.root], tmp_path / "out", robot=robot, jobs=1, bootstrap=0, report_formats=("md",))
    assert [r["status"] for r in result.records] == ["no_evidence", "no_evidence"]
    assert result.recordings == {}  # no camera measured anything in any episode: no recording-level fit
    assert all(r["cameras"] == [] for r in result.records)
    assert all("too short" not in c["why"] and "span" in c["why"] for r in result.records
               for c in r["cameras_left_out"])


@pytest.mark.parametrize(("recording_misfit", "departs"), [(1.0, False), (2.0, True)])
def test_an_episode_whose_best_link_fits_as_well_as_the_recordings_does_not_depart(
        swapped: tuple[VideoDatasetTruth, Path, BatchResult], recording_misfit: float, departs: bool) -> None:
    """An episode whose own best link is another, by a misfit within the noise (0.9 against 1.0 deg per pair on the
    recording's link: within 1.25 times) is no link departure; by twice its best it is."""
    from dataclasses import replace

    from framechain.analysis.egomotion.recording import fit_recording

    _truth, _robot, result = swapped
    ((_log, fits),) = result.recordings.items()
    first, *rest = fits[0].episodes
    other = next(name for name in first.link_misfits if name != fits[0].link)
    moved = replace(first, link=other, link_misfits={fits[0].link: recording_misfit, other: 0.9})
    (refit,) = fit_recording([moved, *rest])
    assert refit.link == fits[0].link
    linked = [d for d in refit.departures if d.episode == first.episode and d.what == "link"]
    assert bool(linked) is departs


def test_batch_prints_each_cameras_recording_fit_as_attribute_episodes_does(
        swapped: tuple[VideoDatasetTruth, Path, BatchResult], capsys: pytest.CaptureFixture[str]) -> None:
    """batch's summary names each camera's link across the episodes and the late episode that departs."""
    from framechain.cli.batch_cmd import _print_summary

    truth, _robot, result = swapped
    capsys.readouterr()
    _print_summary(result)
    printed = capsys.readouterr().out.splitlines()
    for camera in truth.cameras:
        (sentence,) = [ln for ln in printed if f"camera {camera.name}_optical_frame: rides {camera.camera_link}" in ln]
        assert f"in the fit of {EPISODES} episode(s)" in sentence
    late = [ln for ln in printed if ln.startswith(f"  episode {LATE_EPISODE}: its offset")]
    assert len(late) == len(truth.cameras)


def test_a_camera_placed_from_its_images_gets_one_position_for_the_recording(tmp_path: Path, so101_urdf: Path) -> None:
    """Without robot.yaml each episode fits the camera's position on its link from its images; the recording gives
    one position, the median of its explained episodes', with how far the farthest lies, in its sentence and in
    recording.json (the generator's camera sits 5.8 cm from gripper_link)."""
    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(
        so101_urdf, seed=11, episodes=2, duration_s=5.0, video_delay_s=0.03))
    written = tmp_path / "out" / "robot.yaml"  # where attribute --episodes writes the robot.yaml it made
    result = run_batch([truth.root], tmp_path / "out", jobs=1, bootstrap=0, report_formats=("md",),
                       generated_robot_at=written)
    (fit,) = result.recordings[str(truth.root.resolve())]
    assert fit.position_episodes == 2
    fixes = [f["fix"] for record in result.records for f in record["findings"]]
    assert fixes
    assert all(fix.startswith(f"In {written}, set ") for fix in fixes)
    placed = np.array([e.xyz_link_cam for e in fit.episodes])
    assert fit.xyz_link_cam is not None
    assert np.linalg.norm(fit.xyz_link_cam - truth.xyz_link_cam) < 0.01
    assert fit.position_spread_m == pytest.approx(0.5 * np.linalg.norm(placed[0] - placed[1]), abs=1e-9)
    report = (result.table_path.parent / "fleet_report.md").read_text()
    (sentence,) = [line for line in report.splitlines() if "camera wrist_optical_frame: rides" in line]
    shown = ", ".join(f"{v:.3f}" for v in fit.xyz_link_cam)
    assert f"its position, not known, fitted at [{shown}] m (the median of 2 episode(s)" in sentence
    document = json.loads(result.report_paths["recording"].read_text())
    (camera,) = document["recordings"][0]["cameras"]
    assert camera["position"]["xyz_link_cam"] == pytest.approx(fit.xyz_link_cam, abs=1e-6)
