"""A textured world a simulated camera sees: a far panorama and a near table, warped with OpenCV.

Each pixel's ray (its own pinhole maths, never framechain's camera model) is turned into the
world by the camera's pose. A ray that meets the table plane ``z = 0`` inside the table samples the
table texture at the hit point (near: the image shows parallax when the camera translates); every
other ray samples an equirectangular panorama by its direction alone (at infinity: only rotation
moves it). Both are ``cv2.remap`` lookups, so a 224x224 frame renders in a few milliseconds. Parts
of the robot fixed in the camera's view (gripper pads) are painted at fixed pixels over the scene.

Conventions: the camera's optical frame is x right, y down, z forward; ``T_world_cam`` maps
camera points into the world; pixel (0, 0) is the centre of the top-left pixel (OpenCV).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray

__all__ = ["PadRegion", "TexturedScene", "pixel_rays", "png_bytes"]

Image = npt.NDArray[np.uint8]


def pixel_rays(fx: float, fy: float, cx: float, cy: float, width: int, height: int) -> FloatArray:
    """Unit rays of every pixel in the optical frame, ``(height, width, 3)``."""
    u, v = np.meshgrid(np.arange(width, dtype=float), np.arange(height, dtype=float))
    rays = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], axis=-1)
    out: FloatArray = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    return out


def _texture(rng: np.random.Generator, height: int, width: int, shapes: int, radius: tuple[int, int]) -> Image:
    """Multi-scale colour noise with random rectangles and discs (``radius`` px): corners for a tracker."""
    out = np.zeros((height, width, 3), dtype=np.float32)
    for cells, weight in ((4, 60.0), (16, 40.0), (64, 25.0)):
        coarse = rng.random((cells, max(1, cells * width // height), 3)).astype(np.float32)
        out += weight * cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC)
    img = np.clip(out, 0, 255).astype(np.uint8)
    for _ in range(shapes):
        colour = tuple(int(c) for c in rng.integers(0, 256, 3))
        x, y = int(rng.integers(0, width)), int(rng.integers(0, height))
        r = int(rng.integers(*radius))
        if rng.random() < 0.5:
            cv2.rectangle(img, (x - r, y - r // 2), (x + r, y + r), colour, -1)
        else:
            cv2.circle(img, (x, y), r, colour, -1)
    return np.asarray(cv2.GaussianBlur(img, (0, 0), 1.0), dtype=np.uint8)


def _cloth(rng: np.random.Generator, side: int, px_per_m: float) -> Image:
    """A cloth over the table: one colour, a faint weave (4 mm threads), soft folds and a few small stains.

    Little for a tracker to hold on to: the weave is a few grey levels deep and repeats (its corners
    alias), the folds are smooth, and only the stains are corners worth the name.
    """
    y, x = np.mgrid[0:side, 0:side].astype(np.float32)
    period = max(2.0, 0.004 * px_per_m)
    weave = 4.0 * np.sin(2 * np.pi * x / period) * np.sin(2 * np.pi * y / period)
    coarse = rng.random((6, 6)).astype(np.float32)
    folds = 30.0 * (cv2.resize(coarse, (side, side), interpolation=cv2.INTER_CUBIC) - 0.5)
    base = np.array([96.0, 112.0, 140.0], dtype=np.float32)
    img = np.clip(base[None, None, :] + (weave + folds)[..., None], 0, 255).astype(np.uint8)
    for _ in range(int(side * side / 2500)):
        colour = tuple(int(c) for c in base + rng.uniform(-45, 45, 3))
        cv2.circle(img, (int(rng.integers(0, side)), int(rng.integers(0, side))),
                   int(rng.integers(2, max(3, int(0.02 * px_per_m)))), colour, -1)
    return np.asarray(cv2.GaussianBlur(img, (0, 0), 0.8), dtype=np.uint8)


@dataclass(frozen=True)
class PadRegion:
    """A part of the robot fixed in the image: a filled polygon of pixels and its texture seed."""

    polygon: tuple[tuple[int, int], ...]
    seed: int


class TexturedScene:
    """A table (``|x|, |y| <= half_size_m`` on ``z = 0``) under a panorama, rendered per camera pose."""

    def __init__(
        self, rng: np.random.Generator, *, half_size_m: float = 1.0, table_px_per_m: float = 500.0,
        panorama_height: int = 720, noise_sigma: float = 1.5, table_style: str = "rich",
    ) -> None:
        self.half_size_m = half_size_m
        self.table_px_per_m = table_px_per_m
        side = round(2 * half_size_m * table_px_per_m)
        # Shapes of 1-4 cm on the table, of 1-5 degrees in the panorama.
        lo, hi = max(2, int(0.01 * table_px_per_m)), max(4, int(0.04 * table_px_per_m))
        if table_style == "rich":
            self.table = _texture(rng, side, side, shapes=int(3 * (side / lo) ** 2 / 16), radius=(lo, hi))
        elif table_style == "cloth":
            self.table = _cloth(rng, side, table_px_per_m)
        else:
            raise ValueError(f"table_style {table_style!r}: rich or cloth")
        deg = panorama_height / 180.0
        self.panorama = _texture(rng, panorama_height, 2 * panorama_height, shapes=panorama_height * 3,
                                 radius=(max(2, int(deg)), max(4, int(5 * deg))))
        # Sensor noise: a few fields drawn once and cycled (drawing one per frame costs more than the render).
        self._noise: list[npt.NDArray[np.int16]] = []
        self.noise_sigma = noise_sigma
        self._noise_seed = int(rng.integers(2**32))
        self._frames = 0
        self._pad_cache: dict[tuple[int, int, PadRegion], tuple[npt.NDArray[np.bool_], Image]] = {}

    def paint_marker(self, dictionary: int, marker_id: int, centre_xy_m: tuple[float, float], size_m: float) -> None:
        """An ArUco/AprilTag marker of OpenCV's predefined ``dictionary`` lying on the table, its black square
        ``size_m`` wide centred at ``centre_xy_m``, with a white margin of one cell, readable from above: its
        image x axis along the world +x, its image y axis (down the printed marker) along the world -y. The
        table texture's rows follow +y, so the marker is painted upside down in it."""
        scale = self.table_px_per_m
        side = round(size_m * scale)
        marker = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(dictionary), marker_id, side)
        cell = max(1, side // 6)
        patch = cv2.copyMakeBorder(marker, cell, cell, cell, cell, cv2.BORDER_CONSTANT, value=255)
        x0 = round((centre_xy_m[0] + self.half_size_m) * scale - patch.shape[1] / 2)
        y0 = round((centre_xy_m[1] + self.half_size_m) * scale - patch.shape[0] / 2)
        self.table[y0:y0 + patch.shape[0], x0:x0 + patch.shape[1]] = patch[::-1, :, None]

    def place_marker(self, world_from_cam: FloatArray, dictionary: str, marker_id: int, size_m: float
                     ) -> tuple[float, float, float]:
        """Paint a marker where the camera's optical axis meets the table, on median over its poses
        ``world_from_cam`` (T, 4, 4); its centre in the world."""
        axis = world_from_cam[:, :3, 2]
        centre = world_from_cam[:, :3, 3]
        down = axis[:, 2] < -0.1
        depth = -centre[down, 2] / axis[down, 2]
        hits = centre[down, :2] + depth[:, None] * axis[down, :2]
        x, y = (float(v) for v in np.median(hits, axis=0))
        self.paint_marker(int(getattr(cv2.aruco, dictionary)), marker_id, (x, y), size_m)
        return (x, y, 0.0)

    def render(self, world_from_cam: FloatArray, rays: FloatArray, pads: tuple[PadRegion, ...] = ()) -> Image:
        """One RGB frame: ``rays`` from :func:`pixel_rays`, ``world_from_cam`` a 4x4 pose."""
        rot, centre = world_from_cam[:3, :3], world_from_cam[:3, 3]
        d = rays.astype(np.float32) @ rot.T.astype(np.float32)  # (H, W, 3) world directions
        lon = np.arctan2(d[..., 1], d[..., 0])
        lat = np.arcsin(np.clip(d[..., 2], -1.0, 1.0))
        ph, pw = self.panorama.shape[:2]
        map_x = ((lon + np.pi) / (2 * np.pi) * pw - 0.5).astype(np.float32)
        map_y = ((np.pi / 2 - lat) / np.pi * ph - 0.5).astype(np.float32)
        far = cv2.remap(self.panorama, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        with np.errstate(divide="ignore", invalid="ignore"):
            depth = -centre[2] / d[..., 2]
        hit_x = centre[0] + depth * d[..., 0]
        hit_y = centre[1] + depth * d[..., 1]
        on_table = (d[..., 2] < 0) & (np.abs(hit_x) < self.half_size_m) & (np.abs(hit_y) < self.half_size_m)
        scale = self.table_px_per_m
        tx = np.where(on_table, (hit_x + self.half_size_m) * scale - 0.5, -1.0).astype(np.float32)
        ty = np.where(on_table, (hit_y + self.half_size_m) * scale - 0.5, -1.0).astype(np.float32)
        near = cv2.remap(self.table, tx, ty, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        img = np.where(on_table[..., None], near, far)
        for pad in pads:
            mask, grey = self._pad(img.shape[0], img.shape[1], pad)
            img[mask] = grey[mask][:, None]
        if self.noise_sigma > 0:
            img = cv2.add(img, self._noise_field(img.shape), dtype=cv2.CV_8U)
        self._frames += 1
        return np.ascontiguousarray(img, dtype=np.uint8)

    def _noise_field(self, shape: tuple[int, ...]) -> npt.NDArray[np.int16]:
        """One of eight seeded noise fields (int16), cycled frame by frame."""
        if not self._noise or self._noise[0].shape != shape:
            rng = np.random.default_rng(self._noise_seed)
            self._noise = [np.round(rng.normal(0.0, self.noise_sigma, shape)).astype(np.int16) for _ in range(8)]
        return self._noise[self._frames % len(self._noise)]

    def _pad(self, h: int, w: int, pad: PadRegion) -> tuple[npt.NDArray[np.bool_], Image]:
        """A textured grey pad, the same pixels in every frame: its mask and texture."""
        key = (h, w, pad)
        if key not in self._pad_cache:
            mask = np.zeros((h, w), dtype=np.uint8)
            cv2.fillPoly(mask, [np.asarray(pad.polygon, dtype=np.int32)], 255)
            rng = np.random.default_rng(pad.seed)
            texture = (40 + 50 * rng.random((h // 6 + 1, w // 6 + 1))).astype(np.float32)
            grey = cv2.resize(texture, (w, h), interpolation=cv2.INTER_NEAREST).astype(np.uint8)
            self._pad_cache[key] = (mask > 0, grey)
        return self._pad_cache[key]


def png_bytes(rgb: FloatArray) -> bytes:
    """An RGB frame encoded as PNG (an image feature's bytes)."""
    ok, data = cv2.imencode(".png", cv2.cvtColor(np.ascontiguousarray(rgb, dtype=np.uint8), cv2.COLOR_RGB2BGR))
    if not ok:
        raise ValueError("cannot encode a frame as PNG")
    return bytes(data.tobytes())
