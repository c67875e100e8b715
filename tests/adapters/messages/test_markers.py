"""Markers found in logged images: rendered markers at known poses (every image encoding, written
with the real writers) and the real Raspberry Pi JPEGs of UbiquityRobotics/fiducials."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain.adapters import open_log
from framechain.config.chain import ChainConfig
from framechain.errors import FramechainError
from framechain.vision.markers import image_pixels
from tests.helpers.realdata import ARUCO_IMAGES_BAG, ARUCO_MARKER_BAG

T0 = 1_700_000_000 * 10**9
K = np.array([[620.0, 0.0, 319.5], [0.0, 620.0, 239.5], [0.0, 0.0, 1.0]])
W, H = 640, 480
SIZE_M = 0.12
DICTIONARY = "DICT_5X5_1000"
SUPERSAMPLE = 4


def _render(ids: list[int], poses: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """A grey image of markers at known poses (camera_from_marker R, t), drawn through the
    homography K [r1 r2 t] at 4x resolution and area-averaged down (anti-aliased edges)."""
    aruco = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, DICTIONARY))
    cells = 7  # 5x5 bits and a one-cell black border
    side_px = cells * 40
    # High-resolution pixel centres: x_hi = 4 x + 1.5 for the low-resolution pixel centre x.
    up = np.array([[SUPERSAMPLE, 0, (SUPERSAMPLE - 1) / 2], [0, SUPERSAMPLE, (SUPERSAMPLE - 1) / 2], [0, 0, 1]])
    k_hi = up @ K
    # Marker image pixel centre (i, j) -> marker plane (X right, Y up), metres.
    step = SIZE_M / side_px
    to_plane = np.array([[step, 0, step / 2 - SIZE_M / 2], [0, -step, SIZE_M / 2 - step / 2], [0, 0, 1]])
    image = np.full((H * SUPERSAMPLE, W * SUPERSAMPLE), 255, dtype=np.uint8)
    for marker_id, (rot, t) in zip(ids, poses, strict=True):
        marker = cv2.aruco.generateImageMarker(aruco, marker_id, side_px)
        homography = k_hi @ np.column_stack([rot[:, 0], rot[:, 1], t]) @ to_plane
        warped = cv2.warpPerspective(marker, homography, (W * SUPERSAMPLE, H * SUPERSAMPLE), flags=cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_CONSTANT, borderValue=255)
        image = np.minimum(image, warped)
    return np.asarray(cv2.resize(image, (W, H), interpolation=cv2.INTER_AREA), dtype=np.uint8)


def _scene(rng: np.random.Generator) -> tuple[list[int], list[tuple[np.ndarray, np.ndarray]]]:
    """Three markers facing the camera with some tilt, side by side, 0.6-1.2 m ahead."""
    ids = [7, 123, 640]
    poses = []
    for x in (-0.25, 0.0, 0.25):
        z = rng.uniform(0.6, 1.2)
        tilt = Rotation.from_rotvec(rng.normal(scale=0.25, size=3))
        rot = (tilt * Rotation.from_rotvec([np.pi, 0.0, 0.0])).as_matrix()
        poses.append((rot, np.array([x * z, rng.uniform(-0.1, 0.1) * z, z])))
    return ids, poses


def _bag_with_images(path: Path, grey: np.ndarray) -> Path:
    """One image per encoding, each on its own topic, plus the CameraInfo (no distortion)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types

    def header(frame: str) -> Any:
        return T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=T0 // 10**9, nanosec=0),
                                        frame_id=frame)

    rgb = np.stack([grey, grey, grey], axis=2)
    images: dict[str, Any] = {}
    for encoding, pixels in (("mono8", grey), ("rgb8", rgb), ("bgr8", rgb)):
        step = pixels.shape[1] * (1 if pixels.ndim == 2 else 3)
        images[f"/cam/{encoding}"] = ("sensor_msgs/msg/Image", T["sensor_msgs/msg/Image"](
            header=header("cam_optical"), height=H, width=W, encoding=encoding, is_bigendian=0, step=step,
            data=np.ascontiguousarray(pixels).reshape(-1)))
    for fmt, ext in (("png", ".png"), ("jpeg", ".jpg")):
        ok, data = cv2.imencode(ext, rgb, [cv2.IMWRITE_JPEG_QUALITY, 95] if fmt == "jpeg" else [])
        assert ok
        images[f"/cam/{fmt}/compressed"] = ("sensor_msgs/msg/CompressedImage", T["sensor_msgs/msg/CompressedImage"](
            header=header("cam_optical"), format=f"bgr8; {fmt} compressed bgr8", data=np.asarray(data).reshape(-1)))
    depth = np.full((H, W), 1000, dtype=np.uint16)
    images["/cam/depth16"] = ("sensor_msgs/msg/Image", T["sensor_msgs/msg/Image"](
        header=header("cam_optical"), height=H, width=W, encoding="16UC1", is_bigendian=0, step=2 * W,
        data=depth.view(np.uint8).reshape(-1)))
    roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    info = T["sensor_msgs/msg/CameraInfo"](
        header=header("cam_optical"), height=H, width=W, distortion_model="plumb_bob", D=np.zeros(5),
        K=K.reshape(-1).copy(), R=np.eye(3).reshape(-1), P=np.column_stack([K, np.zeros(3)]).reshape(-1),
        binning_x=0, binning_y=0, roi=roi)
    with Writer(path) as w:
        conn = w.add_connection("/cam/camera_info", "sensor_msgs/msg/CameraInfo", typestore=ts)
        w.write(conn, T0, ts.serialize_ros1(info, "sensor_msgs/msg/CameraInfo"))
        for topic, (msgtype, msg) in images.items():
            conn = w.add_connection(topic, msgtype, typestore=ts)
            w.write(conn, T0 + 1_000, ts.serialize_ros1(msg, msgtype))
    return path


def _chain(image_topic: str, dictionary: str = DICTIONARY, size_m: float | None = SIZE_M) -> ChainConfig:
    markers: dict[str, Any] = {"dictionary": dictionary}
    if size_m is not None:
        markers["size_m"] = size_m
    return ChainConfig.from_dict({"frames": {"camera": "cam_optical"},
                                  "topics": {"image": image_topic, "camera_info": "/cam/camera_info"},
                                  "evidence": {"markers": markers}})


@pytest.fixture(scope="module")
def rendered(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[int], np.ndarray]:
    ids, poses = _scene(np.random.default_rng(2026))
    grey = _render(ids, poses)
    path = _bag_with_images(tmp_path_factory.mktemp("markers") / "images.bag", grey)
    return path, ids, np.stack([t for _, t in poses])


@pytest.mark.parametrize("topic", ["/cam/mono8", "/cam/rgb8", "/cam/bgr8", "/cam/png/compressed",
                                   "/cam/jpeg/compressed"])
def test_rendered_markers_give_their_centres(rendered: tuple[Path, list[int], np.ndarray], topic: str) -> None:
    path, ids, centres = rendered
    loaded = open_log(path, _chain(topic))
    assert loaded.decoded_topics[topic] == "marker_image"
    assert [t for t in loaded.decoded_topics if t != "/cam/camera_info"] == [topic]  # only the named image topic
    obs = loaded.timeline.observations
    order = np.argsort(obs.label.astype(int))
    assert obs.label[order].tolist() == [str(i) for i in ids]
    recovered = np.column_stack([obs.u, obs.v, obs.depth_m])[order]
    expected_px = (K @ centres.T).T
    expected_px = expected_px[:, :2] / expected_px[:, 2:]
    # Sub-pixel corners on a 60-120 px marker: the centre pixel within 0.1 px, depth within 1 %.
    assert np.abs(recovered[:, :2] - expected_px).max() < 0.1
    assert np.abs(recovered[:, 2] / centres[:, 2] - 1).max() < 0.01
    counts = loaded.timeline.metadata["fiducials"]["counts"][topic]
    assert counts == {"detections": 3, "observations": 3, "bearing_only": 0, "rejected": {}}
    assert max(loaded.timeline.metadata["fiducials"]["corners"]["reprojection_px"]) < 0.2


def test_markers_without_size_are_bearings(rendered: tuple[Path, list[int], np.ndarray]) -> None:
    path, _, centres = rendered
    obs = open_log(path, _chain("/cam/mono8", size_m=None)).timeline.observations
    assert len(obs) == 3
    assert np.isnan(obs.depth_m).all()
    expected_px = (K @ centres.T).T
    got = np.column_stack([obs.u, obs.v])[np.argsort(obs.label.astype(int))]
    # The diagonals' crossing uses no square constraint: a little looser than the PnP centre.
    assert np.abs(got - expected_px[:, :2] / expected_px[:, 2:]).max() < 0.2


def test_unsearchable_encoding_and_bad_dictionary(rendered: tuple[Path, list[int], np.ndarray]) -> None:
    path, _, _ = rendered
    loaded = open_log(path, _chain("/cam/depth16"))
    assert len(loaded.timeline.observations) == 0
    assert any("/cam/depth16: 1 image in an encoding markers cannot be searched in" in n for n in loaded.info.notes)
    with pytest.raises(FramechainError, match=r"evidence.markers.dictionary 'DICT_9X9_7' is not an OpenCV dictionary"):
        open_log(path, _chain("/cam/mono8", dictionary="DICT_9X9_7"))


def test_image_pixels_respects_step() -> None:
    """Rows padded beyond width x channels (step > width) are cut back to the image."""
    grey = np.arange(12, dtype=np.uint8).reshape(3, 4)
    padded = np.zeros((3, 6), dtype=np.uint8)
    padded[:, :4] = grey
    msg = type("Image", (), {"encoding": "mono8", "height": 3, "width": 4, "step": 6, "data": padded.tobytes()})()
    pixels = image_pixels(msg)
    assert pixels is not None
    assert np.array_equal(pixels, grey)


@pytest.mark.parametrize(("name", "ids", "width"), [
    (ARUCO_IMAGES_BAG, [100, 103, 106, 107, 110, 111, 112], 1280), (ARUCO_MARKER_BAG, [1], 1280)])
def test_real_jpegs(realdata: Path, name: str, ids: list[int], width: int) -> None:
    """UbiquityRobotics' test images: 5x5 markers (its default dictionary, DICT_5X5_1000), 0.14 m."""
    path = realdata / name
    chain = ChainConfig.from_dict({
        "frames": {"camera": "raspicam"},
        "topics": {"image": "/raspicam_node/image/compressed", "camera_info": "/raspicam_node/camera_info"},
        "evidence": {"markers": {"dictionary": "DICT_5X5_1000", "size_m": 0.14}}})
    loaded = open_log(path, chain)
    obs = loaded.timeline.observations
    assert sorted(obs.label.astype(int).tolist()) == ids
    assert (obs.depth_m > 0.5).all()
    assert (obs.depth_m < 4.0).all()
    side = loaded.timeline.metadata["fiducials"]["corners"]
    assert max(side["reprojection_px"]) < 1.0
    # Pinhole check, independent of PnP: depth ~ f * size / side length in pixels, for every marker.
    fx = float(loaded.timeline.cameras.K[0, 0, 0])
    corners = np.array(side["corners_px"]).reshape(-1, 4, 2)
    side_px = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).mean(axis=1)
    by_id = dict(zip(side["obs_id"], fx * 0.14 / side_px, strict=True))
    rough = np.array([by_id[i] for i in obs.obs_id.tolist()])
    assert np.abs(obs.depth_m / rough - 1).max() < 0.15
    assert loaded.timeline.cameras.width[0] == width
    # Another family finds nothing in the same image: the dictionary matters.
    other = ChainConfig.from_dict({**chain.to_dict(), "evidence": {"markers": {"dictionary": "DICT_6X6_250"}}})
    assert len(open_log(path, other).timeline.observations) == 0
