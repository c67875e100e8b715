"""A camera's own motion from its images: rotation (and translation direction) between frames.

Evidence like the markers (:mod:`framechain.vision.markers`): from a camera's frames
alone, with its intrinsics, one :class:`~framechain.timeline.EgoMotionTable` row per frame pair,
``R_cam(t0)_cam(t1)`` in the optical frame. The analysis compares these with the rotation forward
kinematics predicts for the camera's link (time offset, mount rotation, which link).

How:

1. Features (``goodFeaturesToTrack``) are tracked frame to frame with pyramidal Lucas-Kanade and
   a forward-backward check; lost tracks are replaced (:func:`track_features`, once per camera).
   Parts of the robot fixed in the image (gripper pads) are found and left out: pixels whose
   brightness barely changes while the scene does, and tracks that stay put while the scene
   moves past them.
2. For each pair of frames ``spans`` apart (consecutive, and chained over a few frames: the
   tracks alive in both), matched pixels become undistorted unit bearing vectors.
3. Rotation-only RANSAC on the bearings gives the inliers and a first rotation
   (:mod:`framechain.vision.two_view`, all pairs at once).
4. Near points (a table under a wrist camera) move with the camera's translation too, and on
   224x224 frames the baseline is too small to tell that translation from a rotation in the
   images alone (an essential matrix, or a free translation, lands on the wrong one of the
   nearly equivalent motions). Given the translation direction the robot's kinematics predicts
   (``translation``), the rotation is fitted with one positive depth per point along it, which
   is well posed; :func:`framechain.analysis.egomotion.fit_camera_motion` iterates this.
   The translation direction measured given the rotation is reported where the parallax
   reaches ``min_parallax_px`` (else NaN).

Frames that repeat the previous one, are black or missing are skipped (``usable``): a repeated
frame shows an earlier moment than its stamp says.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from framechain.arrays import BoolArray, FloatArray, IntArray
from framechain.config.calibration import Intrinsics
from framechain.geometry.camera import CameraModel
from framechain.geometry.rotations import quat_of
from framechain.timeline import EgoMotionTable, TranslationPrior
from framechain.vision.opencv import require_cv2, undistort_normalised
from framechain.vision.two_view import (
    PairBatch,
    off_flow_residuals,
    rotations_along_translation,
    rotations_ransac,
    translation_directions,
)

__all__ = [
    "EgoMotionOptions",
    "FeatureTracks",
    "FramePairCounts",
    "frame_pair_bearings",
    "frame_pair_counts",
    "lucas_kanade_window",
    "measure_egomotion",
    "track_features",
]

GreyImage = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class EgoMotionOptions:
    """Knobs of :func:`track_features` and :func:`measure_egomotion` (pixels at the camera's resolution)."""

    #: Pairs are frames this many usable frames apart (1: consecutive; 3: chained over three).
    spans: tuple[int, ...] = (1, 3)
    max_features: int = 150
    min_distance_px: float = 6.0
    quality: float = 0.005
    #: Lucas-Kanade window and pyramid levels; on frames at most ``small_frame_px`` on their short side the window is
    #: ``small_window_px`` (:func:`lucas_kanade_window`).
    window_px: int = 15
    pyramid_levels: int = 3
    small_window_px: int = 11
    small_frame_px: int = 360
    #: Forward-backward Lucas-Kanade disagreement above which a track is dropped.
    max_track_error_px: float = 0.5
    #: Rotation-only RANSAC inlier threshold (loose: near points move with the translation too).
    ransac_threshold_px: float = 3.0
    ransac_hypotheses: int = 64
    #: Inlier threshold of the final model, and the robust scale its refinement anneals down to.
    inlier_threshold_px: float = 1.0
    refine_iterations: int = 10
    min_inliers: int = 15
    #: Median translation parallax below which the translation direction is NaN.
    min_parallax_px: float = 1.0
    #: A track that moves less than ``fixed_track_px`` while the scene moves ``fixed_scene_px`` is fixed to
    #: the camera (robot parts in view).
    fixed_track_px: float = 1.0
    fixed_scene_px: float = 40.0
    #: Pixels whose brightness varies less than this share of the image's median variation over the
    #: frames (and under ``still_grey_levels``) are fixed in the image; the region is widened by
    #: ``fixed_mask_radius_px`` (a tracker's window) and no track is kept in it.
    still_share: float = 0.2
    still_grey_levels: float = 3.0
    fixed_mask_radius_px: int = 8
    #: A frame whose tracks moved less than this (median, px) from the previous frame repeats it: an encoder
    #: may code a frame sent twice with a residual of a grey level or more (MPEG-4 Part 2), as much as a slow
    #: camera changes a low-texture scene; tracks tell the two apart (generated 224x224 MPEG-4 over cloth:
    #: repeats moved 0.21 px at most, every other frame 1.2 px at least). A genuinely still moment is left out
    #: as well, which costs nothing: it shows no rotation.
    repeat_motion_px: float = 0.3
    seed: int = 0


#: Frame pairs: padded bearings, the stamps of both frames, the match count of each.
_Pairs = tuple[PairBatch, IntArray, IntArray, IntArray]
#: Pairs with enough matched moving features: the positions (among the usable frames) of both frames and the
#: indices of the matched tracks in each.
_Matched = list[tuple[int, int, IntArray, IntArray]]


@dataclass(frozen=True)
class FramePairCounts:
    """What became of the frame pairs ``spans`` apart the usable frames give (within a run of consecutive frames),
    before their motion is measured: the rest are measured, and a measurement leaves out those with too few inliers.
    """

    possible: int
    #: Fewer than ``min_inliers`` moving features tracked into both frames.
    few_matches: int
    #: The later frame not stamped after the earlier one (the pairing gave both one stamp).
    unordered: int

    @property
    def gathered(self) -> int:
        """The pairs whose motion is measured (each measurement keeps those with ``min_inliers`` inliers)."""
        return self.possible - self.few_matches - self.unordered


@dataclass(frozen=True)
class FeatureTracks:
    """Feature tracks through a camera's usable frames (computed once, measured against many priors).

    ``rows[k]`` is the frame (row) index of the k-th usable frame; ``ids[k]`` and ``pixels[k]`` the
    tracks alive in it and their pixels (OpenCV convention); ``fixed`` the ids of tracks found fixed
    in the image (robot parts in view), left out of every pair. ``repeats`` are the frames (rows)
    left out because no track moved from the frame before (a frame sent twice, re-encoded).
    """

    rows: IntArray
    ids: tuple[IntArray, ...]
    pixels: tuple[FloatArray, ...]
    fixed: IntArray
    repeats: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: Per usable frame, the run of consecutive frames (window) it belongs to: no pair spans two (empty: one run).
    segment: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: Per spans and ``min_inliers``: the pairs with enough matched moving features, and how many pairs were possible.
    _matched: dict[tuple[object, ...], tuple[_Matched, int]] = field(
        default_factory=dict, init=False, repr=False, compare=False)
    #: Per intrinsics, stamps and options: the frame pairs and their rotation-only RANSAC, which do not
    #: depend on the translation prior (a fit measures the same tracks against many priors).
    _first: dict[tuple[object, ...], tuple[_Pairs | None, tuple[FloatArray, BoolArray] | None]] = field(
        default_factory=dict, init=False, repr=False, compare=False)


def track_features(
    frames: Sequence[GreyImage] | npt.NDArray[np.uint8], *, usable: npt.ArrayLike | None = None,
    options: EgoMotionOptions | None = None,
) -> FeatureTracks:
    """Lucas-Kanade tracks through the frames (grey ``(H, W)`` uint8, or RGB) whose ``usable`` flag is set.

    ``usable`` (N,) False skips a frame: missing, black, or a repeat of the previous one (a repeated
    frame shows an earlier moment than its stamp says).
    """
    opts = options or EgoMotionOptions()
    keep = np.ones(len(frames), dtype=bool) if usable is None else np.asarray(usable, dtype=bool)
    if keep.shape != (len(frames),):
        raise ValueError(f"track_features: {len(frames)} frames but {keep.size} usable flags")
    rows = np.flatnonzero(keep).astype(np.int64)
    return _track([_grey(frames[int(i)]) for i in rows], rows, opts)


def measure_egomotion(
    tracks: FeatureTracks,
    stamps_ns: npt.ArrayLike,
    intrinsics: Intrinsics,
    *,
    frame: str,
    translation: TranslationPrior | None = None,
    options: EgoMotionOptions | None = None,
    rotations_only: bool = False,
) -> EgoMotionTable:
    """The camera's motion between its frames, one row per pair of usable frames ``spans`` apart.

    ``stamps_ns`` (N,) are the stamps of all frames (tracks index them by row); ``frame`` names the
    optical frame in the table. Without ``translation`` each rotation is rotation-only (near points,
    moved by the translation too, bias it); with it, the rotation is fitted with one positive depth
    per point along the given direction (pairs whose prior is NaN stay rotation-only). Pairs with
    fewer than ``min_inliers`` inliers are left out. ``rotations_only``: the rows and rotations alone, with
    NaN translation directions, residuals and parallax (a fit's trial measurements: a quarter less time).
    """
    opts = options or EgoMotionOptions()
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    focal = 0.5 * (intrinsics.fx + intrinsics.fy)
    pairs, first = _first_rotations(tracks, stamps, intrinsics, opts)
    if pairs is None or first is None:
        return EgoMotionTable.empty()
    batch, s0, s1, matched = pairs
    rotation, inliers = first[0].copy(), first[1].copy()
    prior = np.full((s0.size, 3), np.nan) if translation is None else np.asarray(translation(s0, s1), dtype=float)
    norm = np.linalg.norm(prior, axis=1, keepdims=True)
    known = np.isfinite(norm[:, 0]) & (norm[:, 0] > 0)
    threshold = opts.inlier_threshold_px / focal
    # Each match's residual across the flow of the translation used: the prior's where known, else the measured one.
    residual = np.full(inliers.shape, np.nan)
    if known.any():
        sub = PairBatch(batch.b0[known], batch.b1[known], batch.valid[known])
        direction = prior[known] / norm[known]
        rotation[known], residual[known] = rotations_along_translation(
            sub, rotation[known], direction, sub.valid.astype(float), threshold, opts.refine_iterations)
        inliers[known] = (residual[known] < threshold) & sub.valid
    count = inliers.sum(axis=1)
    keep = count >= opts.min_inliers
    n = int(keep.sum())
    direction_out, rms, parallax = (np.full((n, 3), np.nan), np.full(n, np.nan), np.full(n, np.nan)) if rotations_only \
        else _translations(batch, rotation, inliers, residual, known, keep, focal, opts)
    table = EgoMotionTable(
        frame=np.full(n, frame), stamp0_ns=s0[keep], stamp1_ns=s1[keep],
        quat_xyzw=quat_of(rotation[keep]) if n else np.zeros((0, 4)), direction=direction_out, tracks=matched[keep],
        inliers=count[keep].astype(np.int64), residual_px=rms, parallax_px=parallax,
    )
    return table.take(np.lexsort((table.stamp1_ns, table.stamp0_ns)))


def _translations(batch: PairBatch, rotation: FloatArray, inliers: BoolArray, residual: FloatArray, known: BoolArray,
                  keep: BoolArray, focal: float, opts: EgoMotionOptions) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Of the pairs kept: the translation direction measured given the rotation (NaN under ``min_parallax_px``), the
    RMS residual of the inliers (px; across the measured translation's flow where the prior was unknown) and the
    median parallax of the inliers (px)."""
    measured = translation_directions(batch, rotation, inliers.astype(float))
    if not known.all():
        sub = PairBatch(batch.b0[~known], batch.b1[~known], batch.valid[~known])
        residual[~known] = np.linalg.norm(off_flow_residuals(sub, rotation[~known], measured[~known]), axis=-1)
    residual = np.where(inliers, residual, np.nan)
    u = batch.b1 @ np.swapaxes(rotation, 1, 2)
    flow = np.linalg.norm(u - (u * batch.b0).sum(-1, keepdims=True) * batch.b0, axis=-1)
    with np.errstate(invalid="ignore"):
        parallax = np.nanmedian(np.where(inliers[keep], flow[keep], np.nan), axis=1) * focal
        rms = np.sqrt(np.nanmean(residual[keep] ** 2, axis=1)) * focal
    direction: FloatArray = np.where((parallax >= opts.min_parallax_px)[:, None], measured[keep], np.nan)
    return direction, rms, parallax


def _first_rotations(
    tracks: FeatureTracks, stamps: IntArray, intrinsics: Intrinsics, opts: EgoMotionOptions
) -> tuple[_Pairs | None, tuple[FloatArray, BoolArray] | None]:
    """The frame pairs (:func:`_gather`) and their rotation-only RANSAC, found once per intrinsics, stamps and
    options on ``tracks`` (the RANSAC draws from its own generator seeded by the options: the same each time)."""
    key = (intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy, intrinsics.distortion_model,
           tuple(intrinsics.distortion), stamps.tobytes(), opts)
    if key not in tracks._first:
        pairs = _gather(tracks, stamps, intrinsics, opts)
        threshold = opts.ransac_threshold_px / (0.5 * (intrinsics.fx + intrinsics.fy))
        first = None if pairs is None else rotations_ransac(
            pairs[0], threshold, hypotheses=opts.ransac_hypotheses, rng=np.random.default_rng(opts.seed))
        tracks._first[key] = (pairs, first)
    return tracks._first[key]


def frame_pair_bearings(tracks: FeatureTracks, stamps_ns: npt.ArrayLike, intrinsics: Intrinsics,
                        options: EgoMotionOptions | None = None) -> tuple[PairBatch, IntArray, IntArray] | None:
    """The matched bearings of the frame pairs :func:`measure_egomotion` measures, with both frames' stamps (None:
    no pair has enough matches); gathered once per intrinsics and stamps."""
    pairs, _first = _first_rotations(tracks, np.asarray(stamps_ns, dtype=np.int64), intrinsics,
                                     options or EgoMotionOptions())
    return None if pairs is None else pairs[:3]


def frame_pair_counts(tracks: FeatureTracks, stamps_ns: npt.ArrayLike,
                      options: EgoMotionOptions | None = None) -> FramePairCounts:
    """How many frame pairs the usable frames of ``tracks`` give, and how many are left out before measuring
    (the same for every intrinsics and translation prior: :func:`measure_egomotion` measures the rest)."""
    opts = options or EgoMotionOptions()
    matched, possible = _matched_pairs(tracks, opts)
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    unordered = sum(1 for k0, k1, _a, _b in matched if stamps[tracks.rows[k1]] <= stamps[tracks.rows[k0]])
    return FramePairCounts(possible=possible, few_matches=possible - len(matched), unordered=unordered)


def _matched_pairs(tracks: FeatureTracks, opts: EgoMotionOptions) -> tuple[_Matched, int]:
    """The pairs of usable frames ``spans`` apart (within a run) with at least ``min_inliers`` moving features
    tracked into both, and how many pairs there were (cached on ``tracks``)."""
    key = (opts.spans, opts.min_inliers)
    if key not in tracks._matched:
        n = len(tracks.ids)
        segment = tracks.segment if tracks.segment.size == n else np.zeros(n, dtype=np.int64)
        chosen: _Matched = []
        possible = 0
        for span in opts.spans:
            for k in range(n - span):
                if segment[k] != segment[k + span]:  # tracks never cross a window's edge: not a pair
                    continue
                possible += 1
                ids, a, b = np.intersect1d(tracks.ids[k], tracks.ids[k + span], assume_unique=True,
                                           return_indices=True)
                moving = ~np.isin(ids, tracks.fixed)
                if moving.sum() >= opts.min_inliers:
                    chosen.append((k, k + span, a[moving], b[moving]))
        tracks._matched[key] = (chosen, possible)
    return tracks._matched[key]


def _gather(tracks: FeatureTracks, stamps: IntArray, intrinsics: Intrinsics, opts: EgoMotionOptions) -> _Pairs | None:
    """The frame pairs ``spans`` apart with enough matches: padded bearings, stamps, match counts."""
    chosen, _possible = _matched_pairs(tracks, opts)
    if not chosen:
        return None
    model = intrinsics.camera_model()
    # One OpenCV call for every frame's pixels (each point is undistorted on its own: the same bearings).
    counts = [len(px) for px in tracks.pixels]
    flat = _bearings(model, np.concatenate(tracks.pixels).reshape(-1, 2) if counts else np.zeros((0, 2)))
    bearings = np.split(flat, np.cumsum(counts)[:-1]) if counts else []
    width = max(len(a) for _k0, _k1, a, _b in chosen)
    b0 = np.zeros((len(chosen), width, 3))
    b1 = np.zeros((len(chosen), width, 3))
    valid = np.zeros((len(chosen), width), dtype=bool)
    for i, (k0, k1, a, b) in enumerate(chosen):
        b0[i, : len(a)] = bearings[k0][a]
        b1[i, : len(a)] = bearings[k1][b]
        valid[i, : len(a)] = True
    b0[~valid] = b1[~valid] = (0.0, 0.0, 1.0)
    first = np.array([c[0] for c in chosen])
    second = np.array([c[1] for c in chosen])
    s0, s1 = stamps[tracks.rows[first]], stamps[tracks.rows[second]]
    forward = s1 > s0
    batch = PairBatch(b0[forward], b1[forward], valid[forward])
    return batch, s0[forward], s1[forward], valid[forward].sum(axis=1).astype(np.int64)


def _bearings(model: CameraModel, pixels: FloatArray) -> FloatArray:
    xy = undistort_normalised(model, pixels)
    rays = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)
    out: FloatArray = rays / np.linalg.norm(rays, axis=1, keepdims=True)
    return out


def _grey(image: npt.NDArray[np.uint8]) -> GreyImage:
    if image.ndim == 2:
        return np.ascontiguousarray(image, dtype=np.uint8)
    cv2 = require_cv2()
    return np.asarray(cv2.cvtColor(np.ascontiguousarray(image, dtype=np.uint8), cv2.COLOR_RGB2GRAY), dtype=np.uint8)


def _track(images: list[GreyImage], rows: IntArray, opts: EgoMotionOptions) -> FeatureTracks:
    """Lucas-Kanade tracks through the usable frames; tracks fixed in the image found and left out.

    The parts of the image that do not change while the scene does (:func:`_fixed_region`) are
    masked from the start. A track is also fixed when it stays within ``fixed_track_px`` of where
    it was born while the scene (the median track) moved ``fixed_scene_px``; its neighbourhood is
    masked for new features, and tracks entering the mask are dropped (a tracker window on a
    pad's edge is dragged by the pad). At the end every track born inside the mask is left out.
    """
    state = _Tracker(images[0].shape if images else (0, 0), opts)
    state.fixed_mask[_fixed_region(images, opts)] = 0
    all_ids: list[IntArray] = []
    all_pixels: list[FloatArray] = []
    repeats = np.zeros(len(images), dtype=bool)
    for k, img in enumerate(images):
        if k > 0:
            step, count = state.follow(images[k - 1], img)
            repeats[k] = count >= opts.min_inliers and step < opts.repeat_motion_px
        state.replenish(img)
        all_ids.append(state.ids.copy())
        all_pixels.append(state.pts.astype(np.float64))
    born = np.round(state.birth_log).astype(np.int64)
    inside = state.fixed_mask[np.clip(born[:, 1], 0, state.fixed_mask.shape[0] - 1),
                              np.clip(born[:, 0], 0, state.fixed_mask.shape[1] - 1)] == 0
    fixed = np.union1d(np.fromiter(state.fixed, dtype=np.int64, count=len(state.fixed)), np.flatnonzero(inside))
    keep = np.flatnonzero(~repeats)
    return FeatureTracks(rows=rows[keep], ids=tuple(all_ids[k] for k in keep),
                         pixels=tuple(all_pixels[k] for k in keep), fixed=fixed.astype(np.int64),
                         repeats=rows[repeats])


#: Rows of the image whose spread over the sampled frames :func:`_fixed_region` takes at once.
SPREAD_BAND_ROWS = 8


def _fixed_region(images: list[GreyImage], opts: EgoMotionOptions) -> BoolArray:
    """Pixels fixed in the image (robot parts in view): their brightness barely changes over the frames.

    Measured on up to 60 frames spread over the sequence; empty when the whole image barely
    changes (a still camera shows nothing fixed). Widened by ``fixed_mask_radius_px``.
    """
    cv2 = require_cv2()
    if len(images) < 3:
        return np.zeros(images[0].shape if images else (0, 0), dtype=bool)
    sample = np.stack([images[int(i)] for i in np.linspace(0, len(images) - 1, min(len(images), 60))])
    # Each pixel's spread over the frames, a band of rows at a time: the same sums in the same order (the same
    # numbers), with temporaries of a few MB the allocator keeps, not four the size of the sample that fresh pages
    # back (0.33 s of a 640x480 episode's first pass, 0.01 s in bands).
    spread = np.empty(sample.shape[1:], dtype=np.float32)
    for top in range(0, sample.shape[1], SPREAD_BAND_ROWS):
        band = slice(top, top + SPREAD_BAND_ROWS)
        spread[band] = sample[:, band].astype(np.float32).std(axis=0)
    typical = float(np.median(spread))
    limit = min(opts.still_grey_levels, opts.still_share * typical)
    still = (spread < limit).astype(np.uint8)
    if not still.any():
        return np.zeros(still.shape, dtype=bool)
    # Specks (a textureless spot of the scene) are dropped before widening the region.
    still = cv2.morphologyEx(still, cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    size = 2 * opts.fixed_mask_radius_px + 1
    widened = cv2.dilate(still, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)))
    return np.asarray(widened, dtype=bool)


def lucas_kanade_window(shape: tuple[int, ...], opts: EgoMotionOptions) -> int:
    """``small_window_px`` on frames at most ``small_frame_px`` on their short side, else ``window_px``: a window spans
    a patch of the view (15 px of a 224-px frame is 43 of a 640-px one of the same lens, over which near points
    move apart). Generated 224x224 cameras, 11 px against 15: offsets closer to the truth (18 cameras: median error
    0.95 ms against 1.20, worst 3.3 against 4.4; 8 SO-101 episodes without a robot.yaml: 0.7 against 0.9, worst 1.5
    against 2.5), mounts as close or closer, tracked in half the time (an episode attributed 12% faster)."""
    short = min(shape[:2]) if len(shape) >= 2 else 0
    return opts.small_window_px if 0 < short <= opts.small_frame_px else opts.window_px


class _Tracker:
    """The tracks alive, where each was born, and how far the scene has moved since."""

    def __init__(self, shape: tuple[int, ...], opts: EgoMotionOptions) -> None:
        cv2 = require_cv2()
        self.opts = opts
        self.shape = shape
        self.fixed_mask = np.full(shape[:2], 255, dtype=np.uint8)
        window = lucas_kanade_window(shape, opts)
        self.lk = {"winSize": (window, window), "maxLevel": opts.pyramid_levels,
                   "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.01)}
        self.ids = np.zeros(0, dtype=np.int64)
        self.pts = np.zeros((0, 2), dtype=np.float32)
        self.birth_pts = np.zeros((0, 2), dtype=np.float32)
        self.birth_scene = np.zeros(0)
        self.birth_log = np.zeros((0, 2))  # every track's birth pixel, by id
        self.scene = 0.0  # cumulative median image motion of the tracks
        self.fixed: set[int] = set()

    def follow(self, previous: GreyImage, img: GreyImage) -> tuple[float, int]:
        """Track into ``img`` with a forward-backward check; drop lost tracks and flag fixed ones.

        Returns the median motion (px) of the tracks kept and how many they are.
        """
        if not len(self.pts):
            return float("inf"), 0
        cv2 = require_cv2()
        h, w = img.shape
        new, status, _ = cv2.calcOpticalFlowPyrLK(previous, img, self.pts.reshape(-1, 1, 2), None, **self.lk)
        back, status_back, _ = cv2.calcOpticalFlowPyrLK(img, previous, new, None, **self.lk)
        new = new.reshape(-1, 2)
        ok = (status.reshape(-1) == 1) & (status_back.reshape(-1) == 1)
        ok &= np.linalg.norm(back.reshape(-1, 2) - self.pts, axis=1) < self.opts.max_track_error_px
        ok &= (new[:, 0] >= 0) & (new[:, 0] <= w - 1) & (new[:, 1] >= 0) & (new[:, 1] <= h - 1)
        pixel = np.rint(np.clip(new, 0, [w - 1, h - 1])).astype(np.int64)
        ok &= self.fixed_mask[pixel[:, 1], pixel[:, 0]] > 0
        if ok.any():
            self.scene += float(np.median(np.linalg.norm(new[ok] - self.pts[ok], axis=1)))
        still = ok & (np.linalg.norm(new - self.birth_pts, axis=1) < self.opts.fixed_track_px)
        still &= self.scene - self.birth_scene > self.opts.fixed_scene_px
        for x, y in np.rint(new[still]).astype(int):
            cv2.circle(self.fixed_mask, (int(x), int(y)), self.opts.fixed_mask_radius_px, 0, -1)
        self.fixed.update(self.ids[still].tolist())
        ok &= ~still
        step = float(np.median(np.linalg.norm(new[ok] - self.pts[ok], axis=1))) if ok.any() else float("inf")
        self.ids, self.pts = self.ids[ok], new[ok]
        self.birth_pts, self.birth_scene = self.birth_pts[ok], self.birth_scene[ok]
        return step, int(ok.sum())

    def replenish(self, img: GreyImage) -> None:
        """New features where tracks are few, away from the tracks alive and the fixed parts."""
        if len(self.pts) >= 0.7 * self.opts.max_features:
            return
        found = _detect(img, self.pts, self.fixed_mask, self.opts, self.opts.max_features - len(self.pts))
        first = self.birth_log.shape[0]
        self.ids = np.concatenate([self.ids, np.arange(first, first + len(found))])
        self.pts = np.concatenate([self.pts, found])
        self.birth_pts = np.concatenate([self.birth_pts, found])
        self.birth_scene = np.concatenate([self.birth_scene, np.full(len(found), self.scene)])
        self.birth_log = np.concatenate([self.birth_log, found.astype(np.float64)])


def _detect(img: GreyImage, existing: npt.NDArray[np.float32], fixed_mask: npt.NDArray[np.uint8],
            opts: EgoMotionOptions, count: int) -> npt.NDArray[np.float32]:
    """New corners away from the tracks alive and from the fixed parts of the image."""
    cv2 = require_cv2()
    mask = fixed_mask.copy()
    for x, y in np.rint(existing).astype(int):
        cv2.circle(mask, (int(x), int(y)), int(opts.min_distance_px), 0, -1)
    corners = cv2.goodFeaturesToTrack(img, maxCorners=max(count, 1), qualityLevel=opts.quality,
                                      minDistance=opts.min_distance_px, mask=mask, blockSize=7)
    if corners is None:
        return np.zeros((0, 2), dtype=np.float32)
    return np.asarray(corners, dtype=np.float32).reshape(-1, 2)
