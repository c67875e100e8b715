"""Images of a generated scene: JPEG colour frames (a checkerboard floor, sky, the object as a red disc) and depth
frames registered to the colour camera, each computed with the generator's own maths (:mod:`framechain.sim.rigid`)."""

from __future__ import annotations

import numpy as np

from framechain.arrays import FloatArray, IntArray
from framechain.sim import rigid
from framechain.timeline import DepthFrameTable, ImageFrameTable


def render_color(
    width: int, height: int, optical_frame: str, topic: str, K: FloatArray, world_from_optical: FloatArray,
    stamps: IntArray, u: FloatArray, v: FloatArray,
) -> ImageFrameTable:
    """JPEG colour images: a 0.5 m checkerboard floor (z = 0), sky above the horizon, and the
    object as a red disc where it was detected (what the detector saw)."""
    import io

    from PIL import Image

    cols, rows = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    rays = rigid.back_project(K, cols.ravel(), rows.ravel(), np.ones(cols.size)).astype(np.float32)
    # light tile, dark tile, sky
    palette = np.array([[150, 150, 140], [95, 100, 95], [190, 210, 235]], dtype=np.uint8)
    blobs: list[bytes] = []
    for i in range(stamps.size):  # one image per frame: this loop is over frames, not messages per hop
        dirs = rays @ world_from_optical[i, :3, :3].T.astype(np.float32)
        origin = world_from_optical[i, :3, 3].astype(np.float32)
        down = dirs[:, 2] < -1e-6
        z = np.where(down, -origin[2] / np.where(down, dirs[:, 2], -1.0), np.inf)
        hit = z < 30.0
        x = origin[0] + dirs[:, 0] * np.where(hit, z, 0.0)
        y = origin[1] + dirs[:, 1] * np.where(hit, z, 0.0)
        tile = (np.floor(x * 2.0) + np.floor(y * 2.0)).astype(np.int64) & 1  # 0.5 m tiles
        pix = palette[np.where(hit, tile, 2)].reshape(height, width, 3)
        r2 = (cols - u[i]) ** 2 + (rows - v[i]) ** 2
        pix[r2 <= 9.0**2] = (60, 20, 20)
        pix[r2 <= 7.5**2] = (220, 40, 40)
        out = io.BytesIO()
        Image.fromarray(pix, "RGB").save(out, format="JPEG", quality=90)
        blobs.append(out.getvalue())
    n = stamps.size
    return ImageFrameTable(
        frame=np.full(n, optical_frame), stamp_ns=stamps, log_time_ns=stamps, width=np.full(n, width),
        height=np.full(n, height), encoding=np.full(n, "jpeg"), source=np.full(n, topic),
        video_path=np.full(n, ""), video_time_ns=np.zeros(n, dtype=np.int64), loader=lambda i: blobs[i],
    )


def render_depth(
    width: int,
    height: int,
    optical_frame: str,
    topic: str,
    K: FloatArray,
    world_from_optical: FloatArray,
    stamps: IntArray,
    u: FloatArray,
    v: FloatArray,
    object_depth: FloatArray,
) -> DepthFrameTable:
    """Depth images registered to the colour camera: the floor plane plus a disc at the object.

    The disc carries the measured object depth so the replay's window median returns it exactly
    (to the millimetre); the floor comes from intersecting each pixel's ray with z = 0.
    """
    cols, rows = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    rays = rigid.back_project(K, cols.ravel(), rows.ravel(), np.ones(cols.size))
    images = np.zeros((stamps.size, height, width), dtype=np.float32)
    radius2 = 8.0**2
    for i in range(stamps.size):  # one image per frame: this loop is over frames, not messages per hop
        dirs_world = rays @ world_from_optical[i, :3, :3].T
        origin_z = world_from_optical[i, 2, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(dirs_world[:, 2] < -1e-6, -origin_z / dirs_world[:, 2], 0.0)
        floor = np.where((z > 0) & (z < 20.0), z, 0.0).reshape(height, width)
        disc = (cols - u[i]) ** 2 + (rows - v[i]) ** 2 <= radius2
        floor[disc] = object_depth[i]
        images[i] = floor
    return DepthFrameTable.from_arrays(optical_frame, stamps, images, source=topic)
