"""Timeline tables: validation, and a Parquet round trip that loses nothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from framechain.timeline import (
    CameraTable,
    DepthFrameTable,
    ImageFrameTable,
    InvalidCameraError,
    JointStateTable,
    ObservationTable,
    PointRole,
    PointTable,
    Timeline,
    TimelineError,
    TransformTable,
)
from framechain.timeline.model import TABLE_TYPES
from tests.helpers.reference_maths import random_quats

S = 1_000_000_000


def full_timeline(rng: np.random.Generator) -> Timeline:
    n = 7
    stamps = np.sort(rng.integers(-5 * S, 2**62, size=n))
    transforms = TransformTable.concat([
        TransformTable.from_rows("/map", "odom", stamps, rng.normal(size=(n, 3)), random_quats(rng, n),
                                 log_time_ns=stamps + 17, source="/tf"),
        TransformTable.from_rows("base_link", "caméra_optical", [0], [[0.1, -0.0, 1e-300]], [[-0.5, 0.5, -0.5, 0.5]],
                                 is_static=True, source="/tf_static"),
    ])
    cameras = CameraTable.concat([
        CameraTable.from_intrinsics("cam", fx=612.25, fy=611.5, cx=320.125, cy=239.75, width=640, height=480,
                                    stamp_ns=3, distortion_model="rational_polynomial",
                                    distortion=rng.normal(size=8) * 0.1, source="/camera_info"),
        CameraTable.from_intrinsics("fish", fx=300, fy=300, cx=400, cy=300, width=800, height=600,
                                    distortion_model="equidistant", distortion=[0.1, -0.01, 0.001, 1e-5]),
    ])
    m = 5
    observations = ObservationTable(
        obs_id=np.array([5, 1, 9, 2**40, -3]), stamp_ns=stamps[:m], log_time_ns=stamps[:m] + 1,
        camera_frame=np.array(["cam", "/cam", "fish", "cam", "cam"]), u=rng.uniform(0, 640, m),
        v=rng.uniform(0, 480, m), depth_m=np.array([1.0, np.nan, 0.0, -np.inf, 2.5]),
        label=np.array(["cup", "", "ünïcode 杯", "a,b", "x" * 300]), score=rng.random(m),
        source=np.full(m, "/detections"),
    )
    joints = JointStateTable(
        stamp_ns=np.array([1, 1, 2]), log_time_ns=np.array([4, 4, 5]), joint=np.array(["j1", "j2", "j1"]),
        position=np.array([0.1, -0.2, 0.3]), velocity=np.array([np.nan, 1.0, 2.0]), effort=np.zeros(3),
        source=np.full(3, "/joint_states"),
    )
    points = PointTable(
        frame=np.array(["map", "cam"]), stamp_ns=np.array([10, 20]), log_time_ns=np.array([11, 21]),
        xyz=rng.normal(size=(2, 3)), quat_xyzw=np.array([[np.nan] * 4, [0, 0, 0, 1.0]]),
        role=np.array([PointRole.TARGET.value, PointRole.HOP_CAMERA.value]), obs_id=np.array([-1, 5]),
        source=np.array(["/target", "/debug/cam"]),
    )
    images = rng.uniform(0.2, 5.0, size=(3, 6, 8)).astype(np.float32)
    images[0, 0, 0] = np.nan
    images[1, 2, 3] = 0.0
    images[2, 5, 7] = np.inf
    depth = DepthFrameTable.concat([
        DepthFrameTable.from_arrays("cam", [100, 200], images[:2], source="/depth"),
        DepthFrameTable.from_arrays("cam2", [150], images[2:], source="/depth2"),
    ])
    # camera images: raw pixels, a JPEG's bytes as logged, and a frame of a video file (nothing to store)
    rgb = ImageFrameTable.from_arrays("cam", [100, 200], rng.integers(0, 255, (2, 4, 5, 3)), encoding="bgr8",
                                      source="/image")
    jpeg = b"\xff\xd8\xff\xe0" + bytes(range(256))
    camera_images = ImageFrameTable.concat([rgb, ImageFrameTable(
        frame=["cam", "cam"], stamp_ns=[300, 400], log_time_ns=[301, 401], width=[640, 640], height=[480, 480],
        encoding=["jpeg", "video"], source=["/image/compressed", "observation.images.cam"],
        video_path=["", "/data/videos/file-000.mp4"], video_time_ns=[0, 33_366_666], loader=lambda i: jpeg)])
    metadata = {"source": {"path": "/logs/run 1.mcap", "format": "mcap"}, "span_ns": [int(stamps[0]), 2**62],
                "urdf": {"/robot_description": "<robot name='r'/>"}, "notes": [], "ratio": 0.1, "ok": True,
                "none": None}
    return Timeline(transforms=transforms, cameras=cameras, observations=observations, joint_states=joints,
                    points=points, depth_frames=depth, image_frames=camera_images, metadata=metadata)


def test_parquet_round_trip_is_lossless_for_every_table(tmp_path: Path, rng: np.random.Generator) -> None:
    original = full_timeline(rng)
    original.save(tmp_path / "tl")
    loaded = Timeline.load(tmp_path / "tl")
    assert loaded.equals(original)
    for i in range(3):  # the video frame has no bytes of its own
        assert loaded.image_frames.load(i) == original.image_frames.load(i)
    assert np.array_equal(loaded.image_frames.pixels(1), original.image_frames.pixels(1))
    for name, cls in TABLE_TYPES.items():
        a, b = getattr(original, name), getattr(loaded, name)
        assert len(a) == len(b) > 0, name
        for column, spec in cls.COLUMNS.items():
            x, y = getattr(a, column), getattr(b, column)
            assert x.dtype.kind == y.dtype.kind, (name, column)
            assert x.shape == y.shape, (name, column)
            if spec.dtype == "f8":
                # Bit for bit, including -0.0, subnormals, NaN and Inf.
                assert x.tobytes() == np.ascontiguousarray(y).tobytes(), (name, column)
            else:
                assert x.tolist() == y.tolist(), (name, column)
    for i in range(len(original.depth_frames)):
        px, py = original.depth_frames.load(i), loaded.depth_frames.load(i)
        assert py.dtype == np.float32
        assert px.shape == py.shape
        assert px.tobytes() == py.tobytes()
    assert dict(loaded.metadata) == dict(original.metadata)
    assert loaded.transforms.child.tolist()[-1] == "caméra_optical"
    assert loaded.observations.camera_frame.tolist()[1] == "cam"


def test_round_trip_of_an_empty_timeline(tmp_path: Path) -> None:
    Timeline().save(tmp_path)
    loaded = Timeline.load(tmp_path)
    assert loaded.equals(Timeline())
    for name in TABLE_TYPES:
        assert len(getattr(loaded, name)) == 0
    assert loaded.transforms.translation.shape == (0, 3)
    assert loaded.cameras.K.shape == (0, 3, 3)


def test_equals_sees_a_single_changed_value(tmp_path: Path, rng: np.random.Generator) -> None:
    original = full_timeline(rng)
    other = original.replace(metadata={**original.metadata, "ratio": 0.2})
    assert not original.equals(other)
    obs = original.observations
    nudged = obs.u.copy()
    nudged[2] = np.nextafter(nudged[2], np.inf)
    changed = original.replace(observations=ObservationTable(**{
        **{c: getattr(obs, c) for c in obs.COLUMNS}, "u": nudged}))
    assert not original.equals(changed)
    images = np.stack([original.depth_frames.load(i) for i in range(2)])
    images[1, 0, 0] += 1
    pixels = original.replace(depth_frames=DepthFrameTable.concat([
        DepthFrameTable.from_arrays("cam", [100, 200], images, source="/depth"),
        original.depth_frames.take([2]),
    ]))
    assert original.equals(pixels, check_depth_pixels=False)
    assert not original.equals(pixels)


def test_depth_take_and_concat_keep_pointing_at_the_right_pixels(rng: np.random.Generator) -> None:
    images = rng.random((4, 2, 3)).astype(np.float32)
    table = DepthFrameTable.from_arrays("cam", [1, 2, 3, 4], images)
    picked = table.take(np.array([3, 1]))
    np.testing.assert_array_equal(picked.load(0), images[3])
    np.testing.assert_array_equal(picked.load(1), images[1])
    assert picked.stamp_ns.tolist() == [4, 2]
    both = DepthFrameTable.concat([picked, table.take(np.array([False, False, True, False]))])
    np.testing.assert_array_equal(both.load(2), images[2])
    with pytest.raises(TimelineError, match="no pixel loader"):
        DepthFrameTable.empty().load(0)


# -- validation ----------------------------------------------------------------------------------
def test_columns_must_have_equal_lengths() -> None:
    with pytest.raises(TimelineError, match="column log_time_ns has 1 rows, expected 2"):
        TransformTable(parent=np.array(["a", "a"]), child=np.array(["b", "b"]), stamp_ns=np.array([1, 2]),
                       log_time_ns=np.array([1]), translation=np.zeros((2, 3)),
                       quat_xyzw=np.tile([0, 0, 0, 1.0], (2, 1)), is_static=np.zeros(2, bool),
                       source=np.array(["", ""]))


def test_vector_columns_must_have_their_shape() -> None:
    with pytest.raises(TimelineError, match=r"translation: expected trailing shape \(3,\), got \(2,\)"):
        TransformTable(parent=np.array(["a"]), child=np.array(["b"]), stamp_ns=np.array([1]),
                       log_time_ns=np.array([1]), translation=np.zeros((1, 2)), quat_xyzw=np.array([[0, 0, 0, 1.0]]),
                       is_static=np.zeros(1, bool), source=np.array([""]))


def test_times_must_be_integer_nanoseconds() -> None:
    with pytest.raises(TimelineError, match="not floats"):
        TransformTable.from_rows("a", "b", np.array([0, 1]), np.zeros((2, 3)), np.tile([0, 0, 0, 1.0], (2, 1)),
                                 log_time_ns=np.array([0.5, 1.5]))
    with pytest.raises(TimelineError, match="not floats"):
        PointTable(frame=np.array(["m"]), stamp_ns=np.array([1.5]), log_time_ns=np.array([1]),
                   xyz=np.zeros((1, 3)), quat_xyzw=np.zeros((1, 4)), role=np.array(["target"]),
                   obs_id=np.array([1]), source=np.array([""]))


def test_observation_ids_must_be_unique() -> None:
    with pytest.raises(TimelineError, match="obs_id values must be unique"):
        ObservationTable(obs_id=np.array([1, 1]), stamp_ns=np.array([0, 1]), log_time_ns=np.array([0, 1]),
                         camera_frame=np.array(["c", "c"]), u=np.zeros(2), v=np.zeros(2), depth_m=np.ones(2),
                         label=np.array(["", ""]), score=np.ones(2), source=np.array(["", ""]))


def test_point_roles_are_a_closed_set() -> None:
    with pytest.raises(TimelineError, match="unknown roles \\['guess'\\]"):
        PointTable(frame=np.array(["m"]), stamp_ns=np.array([1]), log_time_ns=np.array([1]),
                   xyz=np.zeros((1, 3)), quat_xyzw=np.zeros((1, 4)), role=np.array(["guess"]),
                   obs_id=np.array([1]), source=np.array([""]))


@pytest.mark.parametrize(("fx", "fy", "match"), [(0.0, 600.0, "must be positive"), (-600.0, 600.0, "must be positive"),
                                                 (600.0, np.nan, "not finite")])
def test_camera_intrinsics_are_checked(fx: float, fy: float, match: str) -> None:
    with pytest.raises(InvalidCameraError, match=match):
        CameraTable.from_intrinsics("cam", fx=fx, fy=fy, cx=320.0, cy=240.0, width=640, height=480, source="/info")


def test_camera_k_all_zero_is_rejected() -> None:
    # An uncalibrated CameraInfo publishes K = 0.
    good = CameraTable.from_intrinsics("/cam", fx=600, fy=600, cx=320, cy=240, width=640, height=480, source="/info")
    columns = {c: getattr(good, c) for c in good.COLUMNS}
    with pytest.raises(InvalidCameraError, match="'cam' on /info: K is all zero"):
        CameraTable(**{**columns, "K": np.zeros((1, 3, 3))})


def test_from_arrow_names_missing_columns() -> None:
    with pytest.raises(TimelineError, match="lacks columns"):
        TransformTable.from_arrow(pa.table({"parent": ["a"]}))


def test_load_refuses_a_directory_that_is_not_a_timeline(tmp_path: Path) -> None:
    with pytest.raises(TimelineError, match="not a saved timeline"):
        Timeline.load(tmp_path)
    Timeline().save(tmp_path)
    (tmp_path / "timeline.json").write_text('{"format": "other@9", "metadata": {}}')
    with pytest.raises(TimelineError, match="unknown timeline format"):
        Timeline.load(tmp_path)


def test_joint_states_wide_keeps_rows_where_all_joints_are_present() -> None:
    joints = JointStateTable(
        stamp_ns=np.array([1, 1, 2, 3, 3]), log_time_ns=np.array([1, 1, 2, 3, 3]),
        joint=np.array(["a", "b", "a", "b", "a"]), position=np.array([0.1, 0.2, 0.3, 0.4, 0.5]),
        velocity=np.zeros(5), effort=np.zeros(5), source=np.full(5, ""),
    )
    stamps, wide = joints.wide(["a", "b"])
    assert stamps.tolist() == [1, 3]
    np.testing.assert_array_equal(wide, [[0.1, 0.2], [0.5, 0.4]])


def test_metadata_numpy_scalars_are_saved_as_numbers(tmp_path: Path) -> None:
    original = Timeline(metadata={"n": np.int64(3), "x": np.float64(0.5), "ok": np.bool_(True), "nan": float("nan")})
    original.save(tmp_path)
    loaded = Timeline.load(tmp_path).metadata
    assert loaded["n"] == 3
    assert type(loaded["n"]) is int
    assert loaded["x"] == 0.5
    assert loaded["ok"] is True
    assert np.isnan(loaded["nan"])


def test_metadata_that_is_not_json_is_a_timeline_error(tmp_path: Path) -> None:
    with pytest.raises(TimelineError, match="JSON-serialisable"):
        Timeline(metadata={"array": np.zeros(3)}).save(tmp_path)


def test_depth_pixels_must_match_the_declared_size(tmp_path: Path) -> None:
    table = DepthFrameTable.from_arrays("cam", [5], np.ones((1, 4, 6)))
    wrong = DepthFrameTable(**{**{c: getattr(table, c) for c in table.COLUMNS}, "width": np.array([7])},
                            loader=table.loader)
    with pytest.raises(TimelineError, match=r"depth frame 0 \(cam at 5 ns\) is \(4, 6\)"):
        Timeline(depth_frames=wrong).save(tmp_path)
