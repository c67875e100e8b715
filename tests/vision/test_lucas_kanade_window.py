"""Lucas-Kanade's window by frame size: 11 px on frames up to 360 px on their short side, 15 px on VGA and more; both
track a known sub-pixel shift of a textured frame."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from framechain.vision.egomotion import EgoMotionOptions, lucas_kanade_window, track_features


def test_the_window_follows_the_frame_s_short_side() -> None:
    opts = EgoMotionOptions()
    assert [lucas_kanade_window(shape, opts) for shape in [(224, 224), (96, 96), (360, 640), (361, 640), (480, 640),
                                                           (720, 1280)]] == [11, 11, 11, 15, 15, 15]


@pytest.mark.parametrize("side", [224, 480])
def test_either_window_tracks_a_known_sub_pixel_shift(side: int) -> None:
    rng = np.random.default_rng(7)
    texture = cv2.GaussianBlur(rng.uniform(0, 255, (side, side)).astype(np.float32), (0, 0), 2.0)
    frame = cv2.normalize(texture, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    shift = np.array([1.3, -0.7])
    moved = cv2.warpAffine(frame, np.array([[1.0, 0.0, shift[0]], [0.0, 1.0, shift[1]]]), (side, side),
                           flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
    tracks = track_features([frame, moved])
    common, first, second = np.intersect1d(tracks.ids[0], tracks.ids[1], return_indices=True)
    assert common.size > 50
    inner = (np.abs(tracks.pixels[0][first] - side / 2) < side / 2 - 20).all(axis=1)  # away from the reflected edge
    moved_by = tracks.pixels[1][second][inner] - tracks.pixels[0][first][inner]
    assert np.abs(np.median(moved_by, axis=0) - shift).max() < 0.05
