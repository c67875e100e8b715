"""Camera models against OpenCV: undistortion to rays, projection, round trips."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt
import pytest

from framechain.geometry.camera import CameraModel, CameraModelError, focal_of_fov, fov_of_focal
from framechain.timeline import CameraTable

K = np.array([[612.5, 0.0, 318.2], [0.0, 609.8, 243.7], [0.0, 0.0, 1.0]])
W, H = 640, 480
DISTORTIONS: dict[str, npt.NDArray[np.float64]] = {
    "plumb_bob": np.array([-0.28, 0.07, 1.2e-3, -8e-4, 0.02]),
    "rational_polynomial": np.array([0.42, -0.11, 6e-4, -3e-4, 0.05, 0.78, -0.02, 0.09]),
    "equidistant": np.array([0.03, -0.012, 0.004, -0.0007]),
}
TIGHT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-16)
# cv::fisheye marks points whose Newton step never falls below eps as invalid (-1e6): count only.
TIGHT_FISHEYE = (cv2.TERM_CRITERIA_COUNT, 100, 0.0)


def ray_angle(x1: np.ndarray, y1: np.ndarray, x2: np.ndarray, y2: np.ndarray) -> np.ndarray:
    """Angle in radians between the rays [x1, y1, 1] and [x2, y2, 1]."""
    a = np.stack([x1, y1, np.ones_like(x1)], axis=1)
    b = np.stack([x2, y2, np.ones_like(x2)], axis=1)
    cross = np.linalg.norm(np.cross(a, b), axis=1)
    out: np.ndarray = np.arctan2(cross, np.sum(a * b, axis=1))
    return out


def opencv_undistort(model: str, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pts = np.stack([u, v], axis=1).reshape(-1, 1, 2).astype(np.float64)
    d = DISTORTIONS[model]
    if model == "equidistant":
        out = cv2.fisheye.undistortPoints(pts, K, d, criteria=TIGHT_FISHEYE)
    else:
        out = cv2.undistortPoints(pts, K, d, criteria=TIGHT)
    out = out.reshape(-1, 2)
    return out[:, 0], out[:, 1]


def random_pixels(rng: np.random.Generator, n: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    return rng.uniform(-0.5, W - 0.5, n), rng.uniform(-0.5, H - 0.5, n)


@pytest.mark.parametrize("model", sorted(DISTORTIONS))
def test_undistorted_rays_agree_with_opencv(rng: np.random.Generator, model: str) -> None:
    camera = CameraModel("cam", K, W, H, model, DISTORTIONS[model])
    u, v = random_pixels(rng)
    x, y = camera.pixel_to_normalized(u, v)
    x_cv, y_cv = opencv_undistort(model, u, v)
    assert float(ray_angle(x, y, x_cv, y_cv).max()) < 1e-6
    assert camera.is_distorted


@pytest.mark.parametrize("model", sorted(DISTORTIONS))
def test_undistortion_is_exact_inverse_of_projection(rng: np.random.Generator, model: str) -> None:
    # Our iteration runs to convergence: the rays reproject onto their pixels to 1e-9 px.
    camera = CameraModel("cam", K, W, H, model, DISTORTIONS[model])
    u, v = random_pixels(rng)
    z = rng.uniform(0.2, 10.0, u.size)
    p = camera.pixel_to_camera(u, v, z)
    np.testing.assert_allclose(p[:, 2], z)
    u2, v2 = camera.project(p)
    np.testing.assert_allclose(u2, u, atol=1e-9)
    np.testing.assert_allclose(v2, v, atol=1e-9)


@pytest.mark.parametrize("model", sorted(DISTORTIONS))
def test_project_agrees_with_opencv(rng: np.random.Generator, model: str) -> None:
    camera = CameraModel("cam", K, W, H, model, DISTORTIONS[model])
    half_fov = 0.55 if model != "equidistant" else 1.2
    angles = rng.uniform(-half_fov, half_fov, size=(1000, 2))
    z = rng.uniform(0.3, 20.0, 1000)
    points = np.stack([np.tan(angles[:, 0]) * z, np.tan(angles[:, 1]) * z, z], axis=1)
    u, v = camera.project(points)
    zero = np.zeros(3)
    if model == "equidistant":
        expected, _ = cv2.fisheye.projectPoints(points.reshape(-1, 1, 3), zero, zero, K, DISTORTIONS[model])
    else:
        expected, _ = cv2.projectPoints(points, zero, zero, K, DISTORTIONS[model])
    expected = expected.reshape(-1, 2)
    np.testing.assert_allclose(u, expected[:, 0], rtol=0, atol=1e-8)
    np.testing.assert_allclose(v, expected[:, 1], rtol=0, atol=1e-8)


def test_pinhole_without_distortion_is_the_design_formula() -> None:
    camera = CameraModel("cam", np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]]), 640, 480)
    np.testing.assert_allclose(camera.pixel_to_camera([380.0], [210.0], [2.0]), [[0.2, -0.1, 2.0]], atol=1e-15)
    assert not camera.is_distorted
    u, v = camera.project([[0.2, -0.1, 2.0]])
    np.testing.assert_allclose([u[0], v[0]], [380.0, 210.0], atol=1e-12)


def test_zero_coefficients_equal_no_distortion(rng: np.random.Generator) -> None:
    u, v = random_pixels(rng, 100)
    plain = CameraModel("cam", K, W, H)
    zeros = CameraModel("cam", K, W, H, "plumb_bob", np.zeros(5))
    np.testing.assert_array_equal(plain.pixel_to_normalized(u, v), zeros.pixel_to_normalized(u, v))


def test_from_table_keeps_model_and_coefficients() -> None:
    table = CameraTable.from_intrinsics(
        "/cam", fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], width=W, height=H,
        distortion_model="rational_polynomial", distortion=DISTORTIONS["rational_polynomial"],
    )
    camera = CameraModel.from_table(table)
    assert camera.frame == "cam"
    assert camera.distortion_model == "rational_polynomial"
    np.testing.assert_array_equal(camera.distortion, DISTORTIONS["rational_polynomial"])
    np.testing.assert_array_equal(camera.K, K)
    assert (camera.width, camera.height) == (W, H)


def test_unknown_distortion_model_is_an_error() -> None:
    with pytest.raises(CameraModelError, match="unknown distortion model 'mei'"):
        CameraModel("cam", K, W, H, "mei", np.zeros(5))


def test_inside_uses_pixel_edges() -> None:
    camera = CameraModel("cam", K, W, H)
    u = np.array([-0.5, -0.51, W - 0.5, W - 0.51, 10.0, 10.0])
    v = np.array([10.0, 10.0, 10.0, 10.0, H - 0.5, -0.5])
    assert camera.inside(u, v).tolist() == [True, False, False, True, False, True]


@pytest.mark.parametrize("model", ["none", *sorted(DISTORTIONS)])
def test_points_not_in_front_of_the_camera_have_no_pixel(model: str) -> None:
    camera = CameraModel("cam", K, W, H, model, DISTORTIONS.get(model, np.zeros(0)))
    u, v = camera.project([[0.1, 0.2, 0.0], [0.1, 0.2, -1.0], [0.0, 0.0, 0.0], [0.1, 0.2, 1.0]])
    assert np.isnan(u[:3]).all()
    assert np.isnan(v[:3]).all()
    assert np.isfinite([u[3], v[3]]).all()


def test_distinct_models_groups_rows_by_their_whole_model() -> None:
    """Rows share a model exactly when frame, size, K, distortion model and its coefficients are equal:
    checked pair by pair against plain Python tuples, on two cameras interleaved and in runs."""
    from framechain.geometry.camera import distinct_models
    from framechain.timeline import CameraTable

    rng = np.random.default_rng(4)
    n = 400
    kinds = [("cam_a", 640, 480, 500.0, "plumb_bob", 5), ("cam_b", 320, 240, 250.0, "equidistant", 4),
             ("cam_a", 640, 480, 501.0, "plumb_bob", 5), ("cam_a", 640, 480, 500.0, "rational_polynomial", 8)]
    # runs of one model, then two cameras alternating message by message
    pick = np.r_[np.repeat([0, 2, 0, 3], 50), np.tile([0, 1], 100)]
    K = np.zeros((n, 3, 3))
    distortion = np.zeros((n, 14))
    for i, k in enumerate(pick):
        f = kinds[k][3]
        K[i] = [[f, 0, kinds[k][1] / 2], [0, f, kinds[k][2] / 2], [0, 0, 1]]
        distortion[i, : kinds[k][5]] = np.linspace(-0.1, 0.1, kinds[k][5]) * (k + 1)
    distortion[pick == 1, 6] = rng.normal(size=(pick == 1).sum())  # beyond its 4 coefficients: ignored
    table = CameraTable(
        frame=np.array([kinds[k][0] for k in pick]), stamp_ns=np.arange(n, dtype=np.int64),
        log_time_ns=np.arange(n, dtype=np.int64), width=np.array([kinds[k][1] for k in pick], dtype=np.int64),
        height=np.array([kinds[k][2] for k in pick], dtype=np.int64), K=K,
        distortion_model=np.array([kinds[k][4] for k in pick]), distortion=distortion,
        n_distortion=np.array([kinds[k][5] for k in pick], dtype=np.int64), source=np.full(n, "/info"),
    )
    rows = rng.integers(0, n, 600)
    models, which = distinct_models(table, rows)

    def key(row: int) -> tuple[object, ...]:
        m = int(table.n_distortion[row])
        return (str(table.frame[row]), int(table.width[row]), int(table.height[row]), tuple(table.K[row].ravel()),
                str(table.distortion_model[row]), tuple(table.distortion[row, :m]))

    keys = [key(int(r)) for r in rows]
    assert len(models) == len(set(keys)) == 4
    for i in range(len(rows)):
        model = models[which[i]]
        assert (model.frame, model.width, model.height, tuple(model.K.ravel()), model.distortion_model,
                tuple(model.distortion)) == keys[i]


@pytest.mark.parametrize("model", [*sorted(DISTORTIONS), "none", "fisheye"])
def test_numpy_and_opencv_paths_of_one_model_agree(rng: np.random.Generator, model: str) -> None:
    """vision.opencv hands OpenCV the model's own coefficients: both undistortions give the same rays."""
    from framechain.vision.opencv import project, undistort_normalised

    camera = CameraModel("cam", K, W, H, model, DISTORTIONS.get(model, DISTORTIONS["equidistant"]))
    layout = {"equidistant": 4, "plumb_bob": 5, "rational_polynomial": 8, "none": 5}[camera.distortion_model]
    assert camera.opencv_distortion().shape == (layout,)
    u, v = random_pixels(rng, 200)
    x, y = camera.pixel_to_normalized(u, v)
    xy = undistort_normalised(camera, np.stack([u, v], axis=1))
    assert ray_angle(x, y, xy[:, 0], xy[:, 1]).max() < 1e-6
    np.testing.assert_allclose(project(camera, np.stack([x, y, np.ones_like(x)], axis=1)), np.stack([u, v], axis=1),
                               atol=1e-6)


def test_focal_length_and_field_of_view_worked_by_hand() -> None:
    # 90 deg across 640 px: the image's half-width subtends 45 deg, so f = 320 px.
    assert focal_of_fov(640, 90.0) == pytest.approx(320.0, rel=1e-12)
    # 60 deg: f = 320 / tan(30 deg) = 320 * sqrt(3).
    assert focal_of_fov(640, 60.0) == pytest.approx(320.0 * 3**0.5, rel=1e-12)
    assert fov_of_focal(640, 320.0 * 3**0.5) == pytest.approx(60.0, rel=1e-12)
