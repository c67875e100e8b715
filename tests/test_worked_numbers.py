"""The worked numbers of DESIGN.md, through the public API."""

from __future__ import annotations

import numpy as np

from framechain.config.chain import ChainFrames
from framechain.replay import replay
from framechain.timeline import CameraTable, ObservationTable, Timeline, TransformTable


def _timeline(body_xyz: tuple[float, float, float]) -> Timeline:
    transforms = TransformTable.concat([
        TransformTable.from_rows("map", "base_link", [0, 2_000_000_000], [body_xyz, body_xyz],
                                 [[0, 0, 0, 1.0], [0, 0, 0, 1.0]], source="/tf"),
        TransformTable.from_rows("/base_link", "camera", [0], [[0.30, 0.0, 0.80]], [[0, 0, 0, 1.0]],
                                 is_static=True, source="/tf_static"),
    ])
    obs = ObservationTable(
        obs_id=np.array([7]), stamp_ns=np.array([1_000_000_000]), log_time_ns=np.array([1_000_000_000]),
        camera_frame=np.array(["camera"]), u=np.array([380.0]), v=np.array([210.0]), depth_m=np.array([2.0]),
        label=np.array(["cup"]), score=np.array([0.9]), source=np.array(["/detections"]),
    )
    cam = CameraTable.from_intrinsics("camera", fx=600, fy=600, cx=320, cy=240, width=640, height=480)
    return Timeline(transforms=transforms, cameras=cam, observations=obs)


def test_design_worked_numbers_through_every_hop() -> None:
    result = replay(_timeline((1.0, 0.5, 0.0)), ChainFrames(camera="camera", body="base_link", world="map"))
    np.testing.assert_allclose(result.p_cam[0], [0.2, -0.1, 2.0], atol=1e-12)
    np.testing.assert_allclose(result.p_body[0], [0.5, -0.1, 2.8], atol=1e-12)
    np.testing.assert_allclose(result.p_world[0], [1.5, 0.4, 2.8], atol=1e-12)
    assert result.counts() == {"total": 1, "replayed": 1, "rejected": {}, "stale": 1}
    hops = result.hops
    assert list(hops.hop) == ["pixel_to_camera", "camera_to_body", "body_to_world"]
    np.testing.assert_allclose(hops.output_xyz[2], [1.5, 0.4, 2.8], atol=1e-12)
    # The pose hop interpolated between samples 1 s either side: gap of 1 s, above the 20 ms budget.
    assert hops.gap_ns[2] == 1_000_000_000
    assert hops.stale[2]
