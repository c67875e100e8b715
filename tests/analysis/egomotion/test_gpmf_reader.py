"""The GPMF reader (:mod:`tests.helpers.gpmf`) on two real GoPro clips, against facts it does not compute itself.

Facts: the sample rates gpmf-parser documents (gyro ~400 Hz on the Hero5, ~200 Hz on the MAX), the
file's own running sample count (TSMP), gravity (9.81 m/s^2 along GoPro's Z, up, at rest), the
MAX's own matrix between its input and output axis orders (MTRX, ORIN, ORIO), the video's length,
karma.mp4's final pan as OpenCV's phase correlation sees it in the images, and the MAX's own
orientation stream (CORI), integrated independently with scipy.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from framechain.adapters.lerobot.video import probe_video
from tests.helpers.gopro_clip import ClipFrames, decode_clip, documented_mount, gyro_link, integrate_rates
from tests.helpers.gpmf import Packet, SensorStream, axes_matrix, camera_orientation, read_packets, read_stream
from tests.helpers.realdata import gopro_clip

GRAVITY = 9.80665
#: karma.mp4's final pan (the camera turns right at up to 45 deg/s) starts at about 11.5 s.
PAN_FROM_S = 11.2


@pytest.fixture(scope="module")
def karma(realdata: Path) -> Path:
    return gopro_clip(realdata, "karma.mp4")


@pytest.fixture(scope="module")
def max_clip(realdata: Path) -> Path:
    return gopro_clip(realdata, "max-heromode.mp4")


@pytest.fixture(scope="module")
def karma_packets(karma: Path) -> list[Packet]:
    return read_packets(karma)


@pytest.fixture(scope="module")
def max_packets(max_clip: Path) -> list[Packet]:
    return read_packets(max_clip)


@pytest.fixture(scope="module")
def karma_gyro(karma: Path, karma_packets: list[Packet]) -> SensorStream:
    return read_stream(karma, "GYRO", packets=karma_packets)


@pytest.fixture(scope="module")
def karma_pan(karma: Path) -> ClipFrames:
    return decode_clip(karma, start_s=PAN_FROM_S)


def test_sample_rates_and_running_counts_match_the_documented_ones(
    karma: Path, max_clip: Path, karma_packets: list[Packet], max_packets: list[Packet]
) -> None:
    for path, packets, gyro_hz in ((karma, karma_packets, 400.0), (max_clip, max_packets, 200.0)):
        gyro = read_stream(path, "GYRO", packets=packets)
        accel = read_stream(path, "ACCL", packets=packets)
        assert gyro.rate_hz == pytest.approx(gyro_hz, rel=0.015), path.name
        assert accel.rate_hz == pytest.approx(200.0, rel=0.015), path.name
        # TSMP counts every sample since the recording started: it ends at our count, and grows by each packet's.
        assert gyro.total_samples[-1] == len(gyro.values)
        np.testing.assert_array_equal(np.diff(gyro.total_samples), gyro.packet_counts[1:])
        assert gyro.units == "rad/s"


def test_samples_span_the_video_and_the_last_packet_keeps_the_rate(karma: Path, karma_gyro: SensorStream) -> None:
    video = probe_video(karma)
    times = karma_gyro.times_s
    assert np.all(np.diff(times) > 0)
    assert times[0] == 0.0
    # The last MP4 sample claims 1.001 s for its 28 samples; spread over that, the gyro would outlast the video.
    assert karma_gyro.packet_counts[-1] < 50
    assert times[-1] == pytest.approx(video.duration_s, abs=0.01)
    spacing = np.diff(times)
    assert spacing[-20:].mean() == pytest.approx(1.0 / karma_gyro.rate_hz, rel=0.02)


def test_max_packets_carry_microsecond_stamps_80_ms_after_their_mp4_time(max_clip: Path,
                                                                       max_packets: list[Packet]) -> None:
    gyro = read_stream(max_clip, "GYRO", packets=max_packets)
    lead = gyro.packet_stmp_s - gyro.packet_start_s
    assert np.all((lead > 0.07) & (lead < 0.095))
    on_stmp = read_stream(max_clip, "GYRO", clock="stmp", packets=max_packets)
    np.testing.assert_allclose(on_stmp.times_s[: gyro.packet_counts[0]] - gyro.times_s[: gyro.packet_counts[0]],
                               lead[0], atol=0.005)


def test_scal_turns_the_accelerometer_into_gravity_along_z_up(
    karma: Path, max_clip: Path, karma_packets: list[Packet], max_packets: list[Packet]
) -> None:
    for path, packets in ((karma, karma_packets), (max_clip, max_packets)):
        accel = read_stream(path, "ACCL", packets=packets)
        assert float(np.median(np.linalg.norm(accel.values, axis=1))) == pytest.approx(GRAVITY, rel=0.03), path.name
    # The Hero5 names no ORIN; its stream name gives the order gpmf-parser documents ("Data order Z,X,Y").
    karma_accel = read_stream(karma, "ACCL", packets=karma_packets)
    assert read_stream(karma, "GYRO", packets=karma_packets).axis_order == "ZXY"
    assert karma_accel.values[:, 0].mean() > 0.95 * GRAVITY  # channel 0 is Z, up: the camera upright on its gimbal
    max_accel = read_stream(max_clip, "ACCL", packets=max_packets)
    assert (axes_matrix(max_accel.axis_order) @ max_accel.values.mean(axis=0))[2] > 0.95 * GRAVITY


def test_max_axis_orders_agree_with_its_own_matrix(max_clip: Path, max_packets: list[Packet]) -> None:
    gyro = read_stream(max_clip, "GYRO", packets=max_packets)
    assert (gyro.axis_order, gyro.output_order) == ("XzY", "ZXY")
    assert gyro.matrix is not None
    # MTRX takes the channels (ORIN) to the output order (ORIO): both name the same GoPro axes.
    np.testing.assert_array_equal(axes_matrix(gyro.output_order) @ gyro.matrix, axes_matrix(gyro.axis_order))


def test_integrated_rates_match_scipy_step_by_step(rng: np.random.Generator) -> None:
    times = np.cumsum(rng.uniform(0.002, 0.004, 300))
    rates = rng.normal(0.0, 2.0, (300, 3))
    expected = Rotation.identity()
    for i in range(299):
        expected = expected * Rotation.from_rotvec(0.5 * (rates[i] + rates[i + 1]) * (times[i + 1] - times[i]))
    got = Rotation.from_quat(integrate_rates(times, rates)[-1])
    assert np.rad2deg((got.inv() * expected).magnitude()) < 1e-9
    constant = integrate_rates(times, np.tile([0.3, -0.2, 0.5], (300, 1)))
    truth = Rotation.from_rotvec(np.outer(times - times[0], [0.3, -0.2, 0.5]))
    assert np.rad2deg((Rotation.from_quat(constant).inv() * truth).magnitude()).max() < 1e-9


def test_karma_final_pan_turns_the_image_as_the_gyro_says(karma_gyro: SensorStream, karma_pan: ClipFrames) -> None:
    cv2 = pytest.importorskip("cv2")
    images = karma_pan.images.astype(np.float32)
    height, width = images.shape[1:]
    centre = (slice(height // 4, 3 * height // 4), slice(width // 4, 3 * width // 4))
    window = cv2.createHanningWindow((width // 2, height // 2), cv2.CV_32F)
    # Horizontal shift of the image centre between consecutive frames (OpenCV: positive when it moves right).
    shift_px = np.array([cv2.phaseCorrelate(a[centre], b[centre], window)[0][0]
                         for a, b in itertools.pairwise(images)])
    t0, t1 = karma_pan.stamps_ns[:-1] * 1e-9, karma_pan.stamps_ns[1:] * 1e-9
    # The gyro's turn about channel 0 (GoPro's Z, up) over each frame interval, for trial lags.
    steps = 0.5 * (karma_gyro.values[1:, 0] + karma_gyro.values[:-1, 0]) * np.diff(karma_gyro.times_s)
    turned = np.r_[0.0, np.cumsum(steps)]
    fits = []
    for lag in np.arange(-0.06, 0.0605, 0.002):
        inside = t1 + lag <= karma_gyro.times_s[-1]
        turn = np.interp(t1 + lag, karma_gyro.times_s, turned) - np.interp(t0 + lag, karma_gyro.times_s, turned)
        px_per_rad = float(turn[inside] @ shift_px[inside] / (turn[inside] @ turn[inside]))
        fits.append((float(np.sqrt(np.mean((shift_px[inside] - px_per_rad * turn[inside]) ** 2))), lag, px_per_rad))
    rms_px, lag, px_per_rad = min(fits)
    assert shift_px.min() < -10.0  # the pan: the scene moves left as the camera turns right
    assert rms_px < 0.3
    assert abs(lag) < 0.04
    # Positive: a turn to the right (negative about up) moves the scene left. A GoPro frame 854 px wide spans
    # 65 to 125 deg: at its centre 390 to 750 px per radian.
    assert 390.0 < px_per_rad < 750.0


def test_max_gyro_integrates_to_its_camera_orientation_stream(max_clip: Path, max_packets: list[Packet]) -> None:
    gyro = read_stream(max_clip, "GYRO", clock="stmp", packets=max_packets)
    cori = read_stream(max_clip, "CORI", clock="stmp", packets=max_packets)
    camera = Rotation.from_quat(camera_orientation(cori))
    # The gyro integrated by this module, carried into the optical frame by GoPro's documented axes.
    body = Slerp(gyro.times_s, Rotation.from_quat(gyro_link(gyro).quat_xyzw))
    mount = Rotation.from_matrix(documented_mount(gyro.axis_order))
    errors = []
    for lag in np.arange(0.0, 0.0301, 0.001):
        inside = (cori.times_s[:-1] + lag >= gyro.times_s[0]) & (cori.times_s[1:] + lag <= gyro.times_s[-1])
        t0, t1 = cori.times_s[:-1][inside], cori.times_s[1:][inside]
        predicted = mount.inv() * body(t0 + lag).inv() * body(t1 + lag) * mount
        measured = camera[:-1][inside].inv() * camera[1:][inside]
        errors.append((float(np.median(np.rad2deg((predicted.inv() * measured).magnitude()))), lag))
    error_deg, lag = min(errors)
    turn_deg = np.rad2deg((camera[:-1].inv() * camera[1:]).magnitude())
    assert np.median(turn_deg) > 0.2  # hand-held while walking: the body turns
    assert error_deg < 0.02
    assert 0.005 < lag < 0.025
