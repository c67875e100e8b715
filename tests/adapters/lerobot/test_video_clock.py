"""How a video's frames pair with a LeRobot episode's rows, decided from the files.

Frame times are written into real mp4 files with PyAV (frame k at k / fps); the rows' stamps are
chosen by hand, so each expected pairing and each row's frame follows from the numbers alone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from framechain.adapters.lerobot.clock import Pairing, episode_frame_times_s, video_clock
from framechain.adapters.lerobot.video import encode_video, read_frames
from framechain.cli.main import main
from tests.helpers.realdata import GR00T


def _video(path: Path, count: int, fps: int = 20) -> Path:
    """``count`` frames, each grey level its own index (so a decoded frame says which frame it is)."""
    frames = np.repeat(np.arange(count, dtype=np.uint8)[:, None, None, None] * 3, 16 * 16 * 3).reshape(
        count, 16, 16, 3)
    return encode_video(path, frames, fps=fps, codec="libx264", options={"qp": "0", "bf": "0"})


@pytest.fixture(scope="module")
def thirty(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _video(tmp_path_factory.mktemp("clock") / "thirty.mp4", 30)


def test_frames_are_counted_in_the_episode_span(thirty: Path) -> None:
    assert episode_frame_times_s(thirty) == pytest.approx(np.arange(30) / 20)
    # An episode from 0.5 s to 1.0 s of a shared file (v3.0): frames 10..19.
    assert episode_frame_times_s(thirty, 0.5, 1.0) == pytest.approx(np.arange(10, 20) / 20)


def test_lerobot_stamps_pair_by_presentation_time(thirty: Path) -> None:
    rows = np.arange(30)
    clock = video_clock("cam", episode_frame_times_s(thirty), rows / 20, rows, fps=20)
    assert clock.pairing is Pairing.PRESENTATION
    assert "LeRobot's convention" in clock.why
    assert clock.file_times_ns(rows / 20) == pytest.approx(rows * 50_000_000)


def test_real_time_stamps_with_a_frame_per_row_pair_by_order(thirty: Path) -> None:
    """30 rows stamped at 18 Hz (the last at 1.61 s, where frame_index / fps says 1.45 s) and 30 frames at
    20 fps: row k holds frame k, although the frame nearest its stamp is another."""
    rows = np.arange(30)
    stamps = rows / 18.0
    clock = video_clock("cam", episode_frame_times_s(thirty), stamps, rows, fps=20)
    assert clock.pairing is Pairing.ORDER
    assert clock.max_departure_s == pytest.approx(29 / 18 - 29 / 20)
    assert clock.stamp_rate_hz == pytest.approx(18.0)
    assert "30 frames for 30 rows" in clock.summary()
    assert "by order" in clock.summary()
    times = clock.file_times_ns(stamps)
    got = read_frames(thirty, times + 50_000)
    levels = got.row_images()[:, 8, 8].astype(int)  # grey
    assert np.abs(levels - rows * 3).max() <= 1  # each row decodes its own frame
    # By presentation time the last row would look 1.61 s in: past the last frame, no frame at all.
    late = read_frames(thirty, clock.file_times_ns(stamps, Pairing.PRESENTATION))
    assert late.missing[-1]


def test_fewer_frames_than_rows_off_the_nominal_rate_fit_a_clock(thirty: Path) -> None:
    """32 rows at 19 Hz against 30 frames: the rows' span mapped onto the frames' (a t + b)."""
    rows = np.arange(32)
    stamps = rows / 19.0
    clock = video_clock("cam", episode_frame_times_s(thirty), stamps, rows, fps=20)
    assert clock.pairing is Pairing.FITTED
    assert clock.scale == pytest.approx((29 / 20) / (31 / 19))
    ends = clock.file_times_ns(stamps[[0, -1]])
    assert ends == pytest.approx([0, 29 * 50_000_000], abs=1000)


def test_a_forced_pairing_wins_and_says_so(thirty: Path) -> None:
    rows = np.arange(30)
    clock = video_clock("cam", episode_frame_times_s(thirty), rows / 18.0, rows, fps=20, forced="presentation")
    assert clock.pairing is Pairing.PRESENTATION
    assert clock.forced
    assert clock.why.startswith("forced in robot.yaml")


def test_capture_stamps_under_each_pairing(thirty: Path) -> None:
    """A frame's capture time under each pairing: its own presentation time, its row's stamp, or the fitted map's
    inverse."""
    rows = np.arange(30)
    stamps = rows / 18.0
    clock = video_clock("cam", episode_frame_times_s(thirty), stamps, rows, fps=20)
    frames_ns = np.array([0, 10, 29]) * 50_000_000
    assert clock.capture_stamps_ns(frames_ns, stamps, Pairing.ORDER) == pytest.approx(
        np.round(stamps[[0, 10, 29]] * 1e9), abs=1)
    assert clock.capture_stamps_ns(frames_ns, stamps, Pairing.PRESENTATION) == pytest.approx(frames_ns, abs=1)
    fitted = clock.capture_stamps_ns(frames_ns, stamps, Pairing.FITTED)
    assert fitted[[0, -1]] == pytest.approx(np.round(stamps[[0, 29]] * 1e9), abs=1000)


def test_a_pairing_that_is_not_one_is_one_line(tmp_path: Path) -> None:
    from framechain.config.calibration import CalibrationError, load_calibration

    path = tmp_path / "cam.yaml"
    path.write_text("name: wrist\nintrinsics: {fx: 100, fy: 100, cx: 50, cy: 50, width: 100, height: 100}\n"
                    "mount: {parent: base, xyz: [0, 0, 0], rpy: [0, 0, 0], optical: true}\n"
                    "timing: {pairing: by_time}\n")
    with pytest.raises(CalibrationError, match=r"timing.pairing: expected one of presentation, order, fitted"):
        load_calibration(path)


def test_info_says_how_a_real_datasets_video_pairs(realdata: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The GR00T sample: 470 rows stamped from 0.05 s (one frame period late) and 470 frames from 0 s: by order,
    which gives row k frame k (by presentation time the last row would have no frame)."""
    dataset = realdata / GR00T
    assert main(["info", str(dataset), "--episode", "2"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert ("video observation.images.ego_view: frames paired with rows by order: one frame per row: 470 frames for "
            "470 rows, timestamps depart from frame_index / fps by up to 0.050 s") in out
