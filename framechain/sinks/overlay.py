"""What the camera saw, per observation: the image nearest it and the chain drawn on that image.

Every sink that draws on camera images (Rerun, the HTML report's crops, the Foxglove export) uses
:func:`image_overlay`, so the pixels agree between them:

- the detection: its pixel, and for fiducials the four corners (from the timeline's fiducial
  side table);
- the recomputed world point and the as-run world point (the robot's logged world point, else its
  target), both projected back into the image through the transforms the replay used at that
  observation (``T_world_cam = T_world_body @ T_body_cam``) and the camera model in force
  (distortion applied, as OpenCV's ``projectPoints``);
- the finding that explains the error (the one with the largest share) and its colour.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.analysis.evidence.alignment import AlignedEvidence
from framechain.analysis.verdict.findings import Finding
from framechain.arrays import BoolArray, FloatArray, IntArray, rows_of
from framechain.geometry.camera import distinct_models
from framechain.replay import ReplayResult
from framechain.replay.stamps import nearest
from framechain.sinks.colors import (
    AS_RUN_COLOR,
    DETECTION_COLOR,
    FAULT_COLORS,
    RECOMPUTED_COLOR,
    UNEXPLAINED_COLOR,
    USED_PIXEL_COLOR,
)
from framechain.sinks.plots import PNG_COMPRESS_LEVEL
from framechain.timeline import PointRole, Timeline, normalize_frame

#: An image within this of an observation's stamp is the one shown with it.
IMAGE_WINDOW_NS = 50_000_000


class ImageSelection(StrEnum):
    """Which camera images a sink shows."""

    ALL = "all"
    NEAR = "near"  # those nearest the observations (within IMAGE_WINDOW_NS)
    NONE = "none"


@dataclass(frozen=True)
class ImageOverlay:
    """Per observation (rows of ``result.observations``): pixels to draw and the image to draw on.

    Pixel arrays are NaN where there is nothing (a rejected observation has no recomputed point;
    a point behind the camera has no pixel). ``image_row`` is the row of ``timeline.image_frames``
    nearest the observation within the window, -1 if none. ``corners_px`` (N, 4, 2) holds the
    detected tag corners where the detection was a fiducial, NaN otherwise. ``detection_uv`` is the pixel
    framechain used; for a tag that is its own estimate of the tag centre from the corners (``estimated``),
    and ``detector_uv`` the centre the detector logged (NaN where it logged none). Elsewhere both are the
    detector's pixel.
    """

    detection_uv: FloatArray  # (N, 2)
    corners_px: FloatArray  # (N, 4, 2)
    detector_uv: FloatArray  # (N, 2)
    estimated: BoolArray  # (N,) detection_uv is framechain's estimate (a tag's centre from its corners)
    recomputed_uv: FloatArray  # (N, 2)
    as_run_uv: FloatArray  # (N, 2)
    as_run_role: str  # "world", "target" or "" (what the as-run pixel is the projection of)
    image_row: IntArray  # (N,)
    width: IntArray  # (N,) image size of the camera model in force (0: none)
    height: IntArray
    finding: Finding | None
    color: tuple[int, int, int]

    def __len__(self) -> int:
        return int(self.image_row.shape[0])

    @property
    def error_px(self) -> FloatArray:
        """Pixel distance between the as-run and recomputed projections (NaN where either lacks one)."""
        out: FloatArray = np.linalg.norm(self.as_run_uv - self.recomputed_uv, axis=1)
        return out

    def inside(self, uv: FloatArray) -> BoolArray:
        """Pixels inside the image (pixel centres at integers: -0.5 .. size - 0.5)."""
        u, v = uv[:, 0], uv[:, 1]
        with np.errstate(invalid="ignore"):
            out: BoolArray = (u >= -0.5) & (v >= -0.5) & (u < self.width - 0.5) & (v < self.height - 0.5)
        return out

    @property
    def detection_colors(self) -> npt.NDArray[np.uint8]:
        """(N, 3) colour of the pixel used: the detection's green where it is the detector's own, light green
        where framechain estimated it."""
        out: npt.NDArray[np.uint8] = np.where(self.estimated[:, None], np.array(USED_PIXEL_COLOR, dtype=np.uint8),
                                              np.array(DETECTION_COLOR, dtype=np.uint8)).astype(np.uint8)
        return out

    def label(self) -> str:
        """What the error line stands for, in a few words."""
        if self.finding is None:
            return "as-run vs recomputed (no finding)"
        return f"{self.finding.fault.value} on {self.finding.hop.value}"


def explaining_finding(findings: Sequence[Finding]) -> Finding | None:
    """The finding with the largest share of the error (None without findings)."""
    return max(findings, key=lambda f: f.share) if findings else None


def project_world_points(timeline: Timeline, result: ReplayResult, p_world: FloatArray) -> FloatArray:
    """Pixels (N, 2) of world points (N, 3), one per observation, through the transforms the replay
    used at that observation and the camera model in force; NaN where either is missing."""
    obs = result.observations
    n = len(obs)
    out = np.full((n, 2), np.nan)
    if n == 0:
        return out
    world_from_cam = result.world_from_body.matrix() @ result.body_from_cam.matrix()
    usable = np.isfinite(world_from_cam).all(axis=(1, 2)) & np.isfinite(p_world).all(axis=1)
    rows = result.camera_row
    usable &= rows >= 0
    usable[usable] = timeline.cameras.width[rows[usable]] > 0  # a camera-less model (3D points) has no pixels
    if not usable.any():
        return out
    rot = world_from_cam[usable, :3, :3]
    trans = world_from_cam[usable, :3, 3]
    # p_cam = R^T (p_world - t), vectorised over observations
    p_cam = np.einsum("nji,nj->ni", rot, p_world[usable] - trans)
    idx = np.flatnonzero(usable)
    models, model_of = distinct_models(timeline.cameras, rows[usable])
    for k, model in enumerate(models):  # one projection per camera model, not per CameraInfo message
        sel = model_of == k
        u, v = model.project(p_cam[sel])
        out[idx[sel], 0], out[idx[sel], 1] = u, v
    return out


def nearest_images(timeline: Timeline, result: ReplayResult, window_ns: int = IMAGE_WINDOW_NS) -> IntArray:
    """Row of ``timeline.image_frames`` nearest each observation among its camera's images, -1 if none within
    the window. With one camera, images of another frame count only when no image has the camera's frame."""
    images = timeline.image_frames
    obs = result.observations
    out = np.full(len(obs), -1, dtype=np.int64)
    if len(images) == 0 or len(obs) == 0:
        return out
    cameras = np.unique(obs.camera_frame).tolist()
    for camera in cameras if len(cameras) > 1 else [result.frames.camera]:
        mine = camera_image_rows(timeline, camera, own_only=len(cameras) > 1)
        sel = np.flatnonzero(obs.camera_frame == camera) if len(cameras) > 1 else np.arange(len(obs))
        if mine.size == 0 or sel.size == 0:
            continue
        stamps = images.stamp_ns[mine]
        pick = nearest(stamps, obs.stamp_ns[sel])
        close = np.abs(stamps[pick] - obs.stamp_ns[sel]) <= window_ns
        out[sel[close]] = mine[pick[close]]
    return out


def camera_image_rows(timeline: Timeline, camera: str, *, own_only: bool = False) -> IntArray:
    """Rows of ``timeline.image_frames`` of a camera, in stamp order (every image when none carries the camera's
    frame and not ``own_only``: one image topic, named by the chain)."""
    images = timeline.image_frames
    mine = np.flatnonzero(images.frame == normalize_frame(camera))
    if mine.size == 0 and not own_only:
        mine = np.arange(len(images))
    order: IntArray = mine[np.argsort(images.stamp_ns[mine], kind="stable")]
    return order


def select_images(timeline: Timeline, result: ReplayResult, selection: ImageSelection,
                  window_ns: int = IMAGE_WINDOW_NS, *, camera: str | None = None) -> IntArray:
    """Rows of ``timeline.image_frames`` a sink shows: all the camera's, those nearest observations, or none
    (``camera``: one camera of a rig, its own images only; None: the chain's camera)."""
    if selection is ImageSelection.NONE:
        return np.zeros(0, dtype=np.int64)
    if selection is ImageSelection.ALL:
        return camera_image_rows(timeline, camera or result.frames.camera, own_only=camera is not None)
    near = nearest_images(timeline, result, window_ns)
    if camera is not None:
        near = near[result.observations.camera_frame == normalize_frame(camera)]
    return np.unique(near[near >= 0])


def fiducial_corners(timeline: Timeline, obs_id: IntArray) -> FloatArray:
    """Detected corners (N, 4, 2) of the observations that are fiducials, NaN for the others."""
    return _fiducial_side(timeline, obs_id, "corners_px", 4).reshape(obs_id.size, 4, 2)


def detector_centres(timeline: Timeline, obs_id: IntArray) -> FloatArray:
    """The centre pixel (N, 2) each fiducial's detector logged, NaN for the others and where it logged none."""
    return _fiducial_side(timeline, obs_id, "detector_centre_px", 1)


def _fiducial_side(timeline: Timeline, obs_id: IntArray, key: str, points: int) -> FloatArray:
    """A pixel column of the fiducial side table (``points`` (u, v) per row) per observation, NaN where none."""
    out = np.full((obs_id.size, 2 * points), np.nan)
    side = (timeline.metadata.get("fiducials") or {}).get("corners") or {}
    ids = np.asarray(side.get("obs_id", []), dtype=np.int64)
    values = side.get(key)
    if ids.size == 0 or values is None:
        return out
    # JSON null (a centre not logged) reads as NaN
    table = np.array(values, dtype=float).reshape(ids.size, 2 * points)
    row = rows_of(ids, obs_id)
    out[row >= 0] = table[row[row >= 0]]
    return out


def image_overlay(
    timeline: Timeline, result: ReplayResult, evidence: AlignedEvidence | None, findings: Sequence[Finding] = (),
    *, window_ns: int = IMAGE_WINDOW_NS,
) -> ImageOverlay:
    """The overlay of every observation of ``result`` (see the module docstring)."""
    obs = result.observations
    n = len(obs)
    recomputed = project_world_points(timeline, result, np.where(result.replayed[:, None], result.p_world, np.nan))
    as_run_uv = np.full((n, 2), np.nan)
    role = ""
    if evidence is not None and len(evidence) == n:
        for candidate, name in ((PointRole.HOP_WORLD, "world"), (PointRole.TARGET, "target")):
            if evidence.present(candidate):
                points = np.where(result.replayed[:, None], evidence.points(candidate), np.nan)
                as_run_uv = project_world_points(timeline, result, points)
                role = name
                break
    rows = result.camera_row
    have = rows >= 0
    width = np.zeros(n, dtype=np.int64)
    height = np.zeros(n, dtype=np.int64)
    width[have] = timeline.cameras.width[rows[have]]
    height[have] = timeline.cameras.height[rows[have]]
    finding = explaining_finding(findings)
    color = UNEXPLAINED_COLOR if finding is None else FAULT_COLORS.get(finding.fault.value, UNEXPLAINED_COLOR)
    detection_uv = np.stack([obs.u, obs.v], axis=1).astype(float)
    no_pixels = have & (width <= 0)
    detection_uv[no_pixels] = np.nan  # a camera-less model's (u, v) are x/z, y/z: not pixels
    corners = fiducial_corners(timeline, obs.obs_id)
    fiducial: BoolArray = np.asarray(np.isfinite(corners).all(axis=(1, 2)))
    detector_uv = np.where(fiducial[:, None], detector_centres(timeline, obs.obs_id), detection_uv)
    # a bearing-only tag keeps the detector's centre: framechain estimated nothing there
    estimated = fiducial & ~(detector_uv == detection_uv).all(axis=1)
    detector_uv[no_pixels] = np.nan
    return ImageOverlay(
        detection_uv=detection_uv, corners_px=corners, detector_uv=detector_uv, estimated=estimated,
        recomputed_uv=recomputed, as_run_uv=as_run_uv, as_run_role=role,
        image_row=nearest_images(timeline, result, window_ns), width=width, height=height, finding=finding,
        color=color,
    )


def as_uint8_rgb(pixels: npt.NDArray[np.generic], encoding: str) -> npt.NDArray[np.uint8]:
    """Raw pixels of an image encoding as (H, W, 3) uint8 RGB for display (depth and mono16 scaled)."""
    arr = np.asarray(pixels)
    if arr.dtype != np.uint8:
        finite = np.isfinite(arr) & (arr > 0)
        top = float(np.percentile(arr[finite], 99)) if finite.any() else 1.0
        arr = np.clip(np.where(finite, arr, 0) / max(top, 1e-9) * 255.0, 0, 255).astype(np.uint8)
    if arr.ndim == 2:
        arr = np.repeat(arr[:, :, None], 3, axis=2)
    if encoding.startswith("bgr"):
        arr = arr[:, :, 2::-1]
    out: npt.NDArray[np.uint8] = np.ascontiguousarray(arr[:, :, :3])
    return out


def worst_rows(timeline: Timeline, result: ReplayResult, overlay: ImageOverlay, score: FloatArray,
               count: int = 4) -> IntArray:
    """Up to ``count`` replayed observations with a (non-video) image and the largest ``score``, at
    least 1/(2 count) of the observations apart so the crops are not four views of one moment."""
    have = np.flatnonzero((overlay.image_row >= 0) & result.replayed)
    if have.size == 0:
        return np.zeros(0, dtype=np.int64)
    have = have[timeline.image_frames.encoding[overlay.image_row[have]] != "video"]
    order = have[np.argsort(-np.nan_to_num(score[have], nan=-np.inf), kind="stable")]
    spacing = max(1, len(overlay) // (2 * count))
    picked: list[int] = []
    for i in order.tolist():
        if all(abs(i - j) >= spacing for j in picked):
            picked.append(i)
            if len(picked) == count:
                break
    return np.asarray(sorted(picked), dtype=np.int64)


def render_crops(
    timeline: Timeline, overlay: ImageOverlay, rows: IntArray, *, width_px: int = 360,
    zoom_px: float | None = None,
) -> list[tuple[int, bytes]]:
    """PNG crops of the camera images at observation ``rows``, with the overlay drawn.

    Returns (observation row, PNG bytes). A crop spans the image and the projected points (grey
    beyond the image), scaled to ``width_px``; with ``zoom_px``, a square of that half-size around
    the points instead (at least), its pixels enlarged as they are, so that a gap of a pixel or two
    shows. JPEG/PNG are decoded with Pillow only to draw the report; frames of video files are
    skipped (nothing here decodes video).
    """
    import io

    from PIL import Image, ImageDraw

    images = timeline.image_frames
    used_colors = overlay.detection_colors
    out: list[tuple[int, bytes]] = []
    for i in rows.tolist():
        if overlay.image_row[i] < 0 or images.encoding[overlay.image_row[i]] == "video":
            continue
        picture = _picture(timeline, int(overlay.image_row[i]))
        w, h = picture.size
        points = [p for p in (overlay.detection_uv[i], overlay.recomputed_uv[i], overlay.as_run_uv[i])
                  if np.isfinite(p).all()]
        pts = np.array(points) if points else np.zeros((0, 2))
        u0, v0, u1, v1 = _crop_window(pts, w, h, zoom_px)
        canvas = Image.new("RGB", (u1 - u0, v1 - v0), (200, 200, 200))
        canvas.paste(picture, (-u0, -v0))
        scale = width_px / canvas.width
        size = (width_px, max(1, round(canvas.height * scale)))
        # zoomed: each image pixel a block, as it is
        canvas = canvas.resize(size) if zoom_px is None else canvas.resize(size, Image.Resampling.NEAREST)
        draw = ImageDraw.Draw(canvas)

        def at(p: FloatArray, *, scale: float = scale, u0: int = u0, v0: int = v0) -> tuple[float, float]:
            # pixel centres at integers: the centre of pixel (u, v) is at u + 0.5 on the canvas
            return (float(p[0]) - u0 + 0.5) * scale, (float(p[1]) - v0 + 0.5) * scale

        def dot(p: FloatArray, color: tuple[int, int, int], r: float, *, draw: ImageDraw.ImageDraw = draw) -> None:
            x, y = at(p)
            draw.ellipse([x - r, y - r, x + r, y + r], fill=color, outline=(0, 0, 0))

        if np.isfinite(overlay.corners_px[i]).all():
            draw.polygon([at(c) for c in overlay.corners_px[i]], outline=DETECTION_COLOR, width=2)
        if np.isfinite(overlay.recomputed_uv[i]).all() and np.isfinite(overlay.as_run_uv[i]).all():
            draw.line([at(overlay.recomputed_uv[i]), at(overlay.as_run_uv[i])], fill=overlay.color, width=3)
            dot(overlay.as_run_uv[i], AS_RUN_COLOR, 5)
        if overlay.estimated[i] and np.isfinite(overlay.detector_uv[i]).all():
            dot(overlay.detector_uv[i], DETECTION_COLOR, 7)
        r, g, b = (int(c) for c in used_colors[i])
        dot(overlay.detection_uv[i], (r, g, b), 5 if overlay.estimated[i] else 7)
        if np.isfinite(overlay.recomputed_uv[i]).all():
            dot(overlay.recomputed_uv[i], RECOMPUTED_COLOR, 4)
        buf = io.BytesIO()
        canvas.save(buf, format="PNG", compress_level=PNG_COMPRESS_LEVEL)
        out.append((i, buf.getvalue()))
    return out


def _picture(timeline: Timeline, row: int) -> Any:
    """Row ``row`` of the timeline's images as an RGB Pillow image (JPEG/PNG decoded, raw pixels converted)."""
    import io

    from PIL import Image

    images = timeline.image_frames
    enc = str(images.encoding[row])
    if enc in ("jpeg", "png"):
        with Image.open(io.BytesIO(images.load(row))) as src:
            return src.convert("RGB")
    return Image.fromarray(as_uint8_rgb(images.pixels(row), enc), "RGB")


def _crop_window(points: FloatArray, w: int, h: int, zoom_px: float | None) -> tuple[int, int, int, int]:
    """(u0, v0, u1, v1) of a crop: the image and the points (within one image size of it), or with ``zoom_px`` a
    square around the points (their spread and ``zoom_px`` either side)."""
    if zoom_px is not None and points.size:
        centre = (points.min(axis=0) + points.max(axis=0)) / 2 + 0.5  # pixel centres at integers
        half = max(float(zoom_px), float(np.ptp(points, axis=0).max()) / 2 + zoom_px / 2)
        u0, v0 = (int(np.floor(c - half)) for c in centre)
        side = int(np.ceil(2 * half))
        return u0, v0, u0 + side, v0 + side
    margin = 0.05 * max(w, h)  # around points outside the image; none when all are inside
    lo = points.min(axis=0) - margin if points.size else np.zeros(2)
    hi = points.max(axis=0) + margin if points.size else np.array([w, h], dtype=float)
    u0, v0 = int(np.floor(max(min(0.0, lo[0]), -w))), int(np.floor(max(min(0.0, lo[1]), -h)))
    u1, v1 = int(np.ceil(min(max(float(w), hi[0]), 2.0 * w))), int(np.ceil(min(max(float(h), hi[1]), 2.0 * h)))
    return u0, v0, u1, v1
