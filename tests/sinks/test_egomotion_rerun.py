"""``framechain replay --save`` of a generated episode as recorded: the video under the camera's pinhole with the
FK frame tree, and the camera's rotation rate from its images against forward kinematics, read back with
Rerun's own reader; the curves are shifted by the video's injected delay (the generator's truth)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from framechain.cli.main import main
from framechain.sim.lerobot_video import VideoDatasetSpec, generate_video_dataset, write_robot_yaml

DELAY_S = 0.100


def series(rrd: Path, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """(episode_time ns, value) of a Scalars entity, in time order."""
    from rerun.chunk import RrdReader

    times, values = [], []
    for chunk in RrdReader(rrd).stream():
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        times.append(np.asarray(batch.column("episode_time").cast("int64")))
        values.append(np.array([v[0] for v in batch.column("Scalars:scalars").to_pylist()]))
    t, v = np.concatenate(times), np.concatenate(values)
    order = np.argsort(t)
    return t[order], v[order]


def test_the_rotation_rate_curves_are_shifted_by_the_video_delay(tmp_path: Path, so101_urdf: Path) -> None:
    from rerun.chunk import RrdReader

    truth = generate_video_dataset(tmp_path / "dataset", VideoDatasetSpec(
        so101_urdf, seed=91, duration_s=4.0, version="v3.0", video_delay_s=DELAY_S))
    robot = write_robot_yaml(truth, tmp_path / "robot.yaml")
    rrd = tmp_path / "episode.rrd"
    assert main(["replay", str(truth.root), "--episode", "0", "--robot", str(robot), "--save", str(rrd), "-q"]) == 0
    rows: dict[str, int] = {}
    for chunk in RrdReader(rrd).stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    assert rows["/camera"] >= 1  # the pinhole
    assert rows["/camera/video"] >= 120  # the asset and one reference per frame
    assert rows.get("/tf/gripper_link", 0) >= 120  # the FK frame tree
    # The findings are entries on the timeline (the viewer's text log view does not list static ones).
    logged = [chunk for chunk in RrdReader(rrd).stream() if chunk.entity_path == "/log/findings"]
    assert logged
    assert not any(chunk.is_static for chunk in logged)
    texts = [t for chunk in logged for t in chunk.to_record_batch().column("TextLog:text").to_pylist()]
    assert any("latency" in str(t) for t in texts)
    measured = series(rrd, "/series/rotation_rate_deg_s/wrist/measured")
    declared = series(rrd, "/series/rotation_rate_deg_s/wrist/declared")
    corrected = series(rrd, "/series/rotation_rate_deg_s/wrist/corrected")
    assert len(measured[0]) > 80
    # By eye: the measured curve is the declared one, later by the delay. The shift that best lines
    # them up, to a millisecond, from the curves as Rerun stores them.
    grid = np.arange(measured[0][0], measured[0][-1], 1_000_000)
    shifts = np.arange(-200, 201) * 1_000_000

    def misfit(shift: int) -> float:
        a = np.interp(grid, measured[0], measured[1])
        b = np.interp(grid - shift, declared[0], declared[1], left=np.nan, right=np.nan)
        return float(np.nanmean((a - b) ** 2))

    best = shifts[int(np.argmin([misfit(int(s)) for s in shifts]))]
    assert best * 1e-9 == pytest.approx(DELAY_S, abs=0.015)
    # The fitted prediction lies on the measured one; the declared one does not.
    common = np.intersect1d(measured[0], corrected[0])
    m = np.interp(common, *measured)
    assert np.median(np.abs(m - np.interp(common, *corrected))) < 0.3 * np.median(np.abs(m - np.interp(common,
                                                                                                        *declared)))
