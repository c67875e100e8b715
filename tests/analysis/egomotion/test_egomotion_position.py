"""A camera's position on its link, fitted from matched bearings (framechain.analysis.egomotion.position).

The scene is made here with scipy's rotations and a pinhole written out by hand: a link turning and moving
along smooth curves, a camera 6 cm from its origin, points a wrist camera would see (0.2 to 1 m in front of
it), projected through a 180 px lens and read back through a 150 px one, with 0.2 px of noise and 3% of the
matches wrong (anywhere in the image).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain.analysis.egomotion.model import LinkMotion
from framechain.analysis.egomotion.position import fit_position
from framechain.vision.two_view import PairBatch

TRUE_FOCAL_PX = 180.0
ASSUMED_FOCAL_PX = 150.0
TRUE_XYZ = np.array([0.05, 0.01, -0.03])
TRUE_MOUNT = Rotation.from_euler("xyz", [100.0, 5.0, -85.0], degrees=True)
#: The frames show the link this much later than their stamps say.
TRUE_OFFSET_S = 0.02


def _link_rotation(t: np.ndarray) -> Rotation:
    return Rotation.from_rotvec(np.stack([0.6 * np.sin(2.2 * t), 0.5 * np.sin(1.4 * t + 1.0),
                                          0.8 * np.sin(1.8 * t + 2.0)], axis=1))


def _link_origin(t: np.ndarray) -> np.ndarray:
    return np.stack([0.3 + 0.1 * np.sin(1.6 * t), 0.1 * np.cos(1.2 * t), 0.2 + 0.05 * np.sin(2.6 * t)], axis=1)


def _about_z(t: np.ndarray) -> Rotation:
    return Rotation.from_rotvec(np.outer(0.8 * np.sin(1.8 * t), [0.0, 0.0, 1.0]))


def _fixed_origin(t: np.ndarray) -> np.ndarray:
    return np.tile([0.3, 0.0, 0.2], (t.size, 1))


def _camera(t: np.ndarray, turn: Callable[[np.ndarray], Rotation], origin: Callable[[np.ndarray], np.ndarray]
            ) -> tuple[Rotation, np.ndarray]:
    """The camera's orientation and centre in the world at times ``t``, its link turned by ``turn`` about its
    ``origin``."""
    link = turn(t)
    return link * TRUE_MOUNT, origin(t) + link.apply(TRUE_XYZ)


def _pixels_to_bearings(pixels: np.ndarray, focal: float) -> np.ndarray:
    rays = np.concatenate([(pixels - 112.0) / focal, np.ones((*pixels.shape[:-1], 1))], axis=-1)
    out: np.ndarray = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    return out


def _scene(seed: int, noise_px: float = 0.2, wrong_share: float = 0.03,
           turn: Callable[[np.ndarray], Rotation] = _link_rotation,
           origin: Callable[[np.ndarray], np.ndarray] = _link_origin
           ) -> tuple[PairBatch, np.ndarray, np.ndarray, LinkMotion]:
    rng = np.random.default_rng(seed)
    link_times = np.arange(0.0, 8.0, 0.01)
    link = LinkMotion(link="gripper_link", stamps_ns=(link_times * 1e9).round().astype(np.int64),
                      quat_xyzw=turn(link_times).as_quat(), xyz=origin(link_times))
    stamps = np.arange(0.5, 7.5, 1.0 / 30.0)
    first = np.concatenate([np.arange(stamps.size - 1), np.arange(stamps.size - 3)])
    second = np.concatenate([first[: stamps.size - 1] + 1, first[stamps.size - 1:] + 3])
    shown0, shown1 = stamps[first] + TRUE_OFFSET_S, stamps[second] + TRUE_OFFSET_S
    rot0, centre0 = _camera(shown0, turn, origin)
    rot1, centre1 = _camera(shown1, turn, origin)
    matches = 60
    # Points in front of the earlier camera, 0.2 to 1 m away, within its 64 deg field of view.
    pixels0 = rng.uniform(10.0, 214.0, size=(first.size, matches, 2))
    depth = rng.uniform(0.2, 1.0, size=(first.size, matches, 1))
    in_cam0 = np.concatenate([(pixels0 - 112.0) / TRUE_FOCAL_PX, np.ones((first.size, matches, 1))], axis=-1) * depth
    world = np.stack([rot0[i].apply(in_cam0[i]) + centre0[i] for i in range(first.size)])
    in_cam1 = np.stack([rot1[i].inv().apply(world[i] - centre1[i]) for i in range(first.size)])
    pixels1 = TRUE_FOCAL_PX * in_cam1[..., :2] / in_cam1[..., 2:] + 112.0
    pixels0 = pixels0 + rng.normal(0.0, noise_px, pixels0.shape)
    pixels1 = pixels1 + rng.normal(0.0, noise_px, pixels1.shape)
    wrong = rng.random((first.size, matches)) < wrong_share
    pixels1[wrong] = rng.uniform(10.0, 214.0, size=(int(wrong.sum()), 2))
    batch = PairBatch(_pixels_to_bearings(pixels0, ASSUMED_FOCAL_PX), _pixels_to_bearings(pixels1, ASSUMED_FOCAL_PX),
                      in_cam1[..., 2] > 0.05)
    to_ns = 1e9
    return batch, (stamps[first] * to_ns).round().astype(np.int64), (stamps[second] * to_ns).round().astype(
        np.int64), link


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_position_mount_focal_length_and_offset_are_found_from_the_link_origin(seed: int) -> None:
    batch, stamps0, stamps1, link = _scene(seed)
    start_mount = TRUE_MOUNT * Rotation.from_rotvec(np.radians([8.0, -6.0, 5.0]))
    fit = fit_position(batch, stamps0, stamps1, link, q_link_cam=start_mount.as_quat(), xyz_link_cam=np.zeros(3),
                       offset_s=0.0, focal_px=ASSUMED_FOCAL_PX, max_offset_s=0.3)
    assert fit is not None
    assert not fit.undetermined
    assert np.linalg.norm(fit.xyz_link_cam - TRUE_XYZ) < 0.004
    assert np.degrees((Rotation.from_quat(fit.q_link_cam).inv() * TRUE_MOUNT).magnitude()) < 0.3
    assert fit.focal_factor * ASSUMED_FOCAL_PX == pytest.approx(TRUE_FOCAL_PX, rel=0.01)
    assert fit.offset_s == pytest.approx(TRUE_OFFSET_S, abs=0.002)
    before, after = fit.residual_px
    # Fitted, the matches misfit by about the noise added (0.2 px per coordinate; the part along the epipolar line is
    # free); at the link's origin, with the start's mount, focal length and offset, five times that.
    assert after < 0.2
    assert before > 4 * after


def test_a_link_without_positions_fits_nothing() -> None:
    batch, stamps0, stamps1, link = _scene(0)
    bare = LinkMotion(link=link.link, stamps_ns=link.stamps_ns, quat_xyzw=link.quat_xyzw, xyz=None)
    assert fit_position(batch, stamps0, stamps1, bare, q_link_cam=TRUE_MOUNT.as_quat(), xyz_link_cam=np.zeros(3),
                        offset_s=0.0, focal_px=ASSUMED_FOCAL_PX, max_offset_s=0.3) is None


def test_a_camera_beyond_the_search_is_said_to_be_at_its_limit() -> None:
    """A position more than POSITION_LIMIT_M from the link's origin on an axis cannot be reached: the fit says which
    unknown stopped at its limit (the caller then does not use it)."""
    batch, stamps0, stamps1, link = _scene(0)
    far_link = LinkMotion(link=link.link, stamps_ns=link.stamps_ns, quat_xyzw=link.quat_xyzw,
                          # The link's origin moved 0.8 m along its own x: the camera is 0.75 m behind it.
                          xyz=link.xyz + Rotation.from_quat(link.quat_xyzw).apply([0.8, 0.0, 0.0]))
    fit = fit_position(batch, stamps0, stamps1, far_link, q_link_cam=TRUE_MOUNT.as_quat(), xyz_link_cam=np.zeros(3),
                       offset_s=0.0, focal_px=ASSUMED_FOCAL_PX, max_offset_s=0.3)
    assert fit is not None
    assert "x" in fit.at_limit.split(", ")


def test_a_link_turning_about_one_axis_leaves_the_position_along_it_undetermined() -> None:
    """A link that only turns about its z axis moves a camera the same wherever it sits along that axis: the fit
    says so (its spread along the link's z is far over the limit), and the other two axes stay determined."""
    batch, stamps0, stamps1, link = _scene(0, turn=_about_z)
    fit = fit_position(batch, stamps0, stamps1, link, q_link_cam=TRUE_MOUNT.as_quat(), xyz_link_cam=np.zeros(3),
                       offset_s=0.0, focal_px=ASSUMED_FOCAL_PX, max_offset_s=0.3)
    assert fit is not None
    assert fit.undetermined.startswith("this motion does not determine it")
    assert abs(fit.spread_axes[0] @ [0.0, 0.0, 1.0]) > 0.99
    assert fit.spread_m[0] > 1.0
    # Across the axis the position is still found: the spread's other axes are small, and so is the error there.
    assert fit.spread_m[1] < 0.005
    across = np.eye(3)[:2]
    assert np.abs(across @ (fit.xyz_link_cam - TRUE_XYZ)).max() < 0.004


def test_a_link_turning_about_a_fixed_point_leaves_the_distance_from_it_undetermined() -> None:
    """A link turning about its fixed origin moves a camera along the same directions wherever it sits on the line
    from the origin through it: the fit says the position is not determined (the spread along that line, or a fit
    at the point itself, which barely moves)."""
    batch, stamps0, stamps1, link = _scene(0, origin=_fixed_origin)
    fit = fit_position(batch, stamps0, stamps1, link, q_link_cam=TRUE_MOUNT.as_quat(), xyz_link_cam=np.zeros(3),
                       offset_s=0.0, focal_px=ASSUMED_FOCAL_PX, max_offset_s=0.3)
    assert fit is not None
    assert fit.undetermined
    # Whatever it says, the fitted point lies on that line: the directions are all the images give.
    along = TRUE_XYZ / np.linalg.norm(TRUE_XYZ)
    off_line = fit.xyz_link_cam - (fit.xyz_link_cam @ along) * along
    assert np.linalg.norm(off_line) < 0.004
