"""A camera's frames from a Timeline's image table, decoded for its ego-motion: grey, in time order, with health.

Whatever the log stored: frames of a video file (a LeRobot mp4, decoded with PyAV, each wanted frame
once: :func:`framechain.adapters.lerobot.video.read_frames`), raw images (packed pixels) or JPEG/PNG
bytes (a LeRobot ``image`` feature, a ``CompressedImage`` topic). Long recordings are measured in
windows of consecutive frames spread over the recording (``max_frames`` in all): tracks never cross
a window's edge, and only the frames of the windows are decoded.

:func:`camera_tracks` tracks features through each window (:func:`~framechain.adapters.messages.
egomotion.track_features`) and merges them into one :class:`FeatureTracks` with disjoint track ids,
so no frame pair spans two windows. :func:`camera_motion_source` puts it together for the analysis: a
camera's frames decoded and tracked once, measured against any translation prior
(:class:`ImageMotion`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.adapters.lerobot.clock import alternative_stamps
from framechain.adapters.lerobot.video import BLACK_LEVEL, BLACK_SHARE, read_frames
from framechain.arrays import BoolArray, FloatArray, IntArray, rows_of
from framechain.config.calibration import Intrinsics
from framechain.geometry.camera import ASSUMED_FOV_DEG, focal_of_fov
from framechain.timeline import EgoMotionTable, ImageFrameTable, Timeline, TranslationPrior, normalize_frame
from framechain.timeline.frames import COMPRESSED_IMAGE_ENCODINGS, RAW_IMAGE_ENCODINGS, VIDEO_ENCODING
from framechain.vision.egomotion import (
    EgoMotionOptions,
    FeatureTracks,
    FramePairCounts,
    frame_pair_bearings,
    frame_pair_counts,
    measure_egomotion,
    track_features,
)
from framechain.vision.opencv import bright_shares, mean_abs_differences, require_cv2
from framechain.vision.two_view import PairBatch

__all__ = [
    "CameraFrames",
    "ImageMotion",
    "camera_frames",
    "camera_image_rows",
    "camera_motion_source",
    "camera_tracks",
    "decode_grey",
    "image_cameras",
    "window_rows",
]

#: Mean absolute difference (grey levels) under which a frame repeats the previous one pixel for pixel: H.264,
#: HEVC and AV1 return a frame sent twice exactly. Re-encoded repeats (MPEG-4 Part 2: a grey level or more off)
#: are found by their tracks instead (``EgoMotionOptions.repeat_motion_px``): a slow camera over a
#: low-texture scene changes its image by less than that.
REPEAT_LEVEL = 0.25


@dataclass(frozen=True)
class CameraFrames:
    """One camera's frames as decoded: grey pixels per row, their stamps, what is usable, the windows.

    ``rows`` are rows of the image table (time order); ``window`` numbers the run of consecutive
    frames each row belongs to. ``usable`` is False for frames missing, black or repeating the
    previous one (a resent frame shows an earlier moment than its stamp).
    """

    frame: str
    rows: IntArray
    stamps_ns: IntArray
    images: npt.NDArray[np.uint8]  # (N, H, W)
    usable: BoolArray
    window: IntArray
    decoded: int
    notes: tuple[str, ...]
    #: Frames repeating the previous one pixel for pixel (within :data:`REPEAT_LEVEL`).
    duplicate: BoolArray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    #: Each row's position among the camera's rows (the frame number a note gives).
    positions: IntArray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __len__(self) -> int:
        return int(self.rows.size)


class ImageMotion:
    """One camera's frames decoded and tracked once; :meth:`measure` measures its motion against a prior.

    ``last`` is the most recent complete measurement (a fit's last). ``pairing`` names how a video's
    frames were paired with the rows ("" for images with stamps of their own), ``alternatives`` the
    frames' capture stamps under the other pairings (-1: no row), for the motion to confirm the pairing.
    """

    def __init__(self, frames: CameraFrames, tracks: FeatureTracks, intrinsics: Intrinsics, *, intrinsics_known: bool,
                 options: EgoMotionOptions | None = None, pairing: str = "", forced: bool = False,
                 alternatives: Mapping[str, IntArray] | None = None) -> None:
        self.camera = frames.frame
        self.frames = len(frames)
        self.decoded = frames.decoded
        self.stamps_ns = frames.stamps_ns
        self.tracks = tracks
        self.intrinsics = intrinsics
        self.intrinsics_known = intrinsics_known
        self.options = options
        self.pairing = pairing
        self.forced = forced
        self.alternatives = dict(alternatives or {})
        notes = [*frames.notes, *_repeat_notes(frames, tracks)]
        if not intrinsics_known:
            notes.append(f"camera {frames.frame} has no intrinsics: measured with an assumed {ASSUMED_FOV_DEG:.0f} "
                         f"deg field of view (fx = {intrinsics.fx:.1f} px); the focal length its motion implies is "
                         "reported")
        self.notes = tuple(notes)
        self.last = EgoMotionTable.empty()

    def rescale_focal(self, factor: float) -> None:
        """Measure from now on with the focal length scaled by ``factor`` (the one the motion implies)."""
        i = self.intrinsics
        self.intrinsics = replace(i, fx=i.fx * factor, fy=i.fy * factor)

    def measure(self, prior: TranslationPrior | None, /, *, rotations_only: bool = False) -> EgoMotionTable:
        table = measure_egomotion(self.tracks, self.stamps_ns, self.intrinsics, frame=self.camera, translation=prior,
                                  options=self.options, rotations_only=rotations_only)
        if not rotations_only:
            self.last = table
        return table

    def pair_bearings(self) -> tuple[PairBatch, IntArray, IntArray] | None:
        """The measured frame pairs' matched bearings (at the focal length measured with) and their frames' stamps."""
        return frame_pair_bearings(self.tracks, self.stamps_ns, self.intrinsics, self.options)

    def pair_counts(self) -> FramePairCounts:
        """The frame pairs the usable frames give and those left out before measuring, under the pairing used."""
        return frame_pair_counts(self.tracks, self.stamps_ns, self.options)

    def restamp(self, table: EgoMotionTable, pairing: str) -> EgoMotionTable:
        """``table`` (measured with this camera's stamps) with its frames' stamps under another ``pairing``."""
        new = self.alternatives[pairing]

        def moved(stamps: IntArray) -> IntArray:
            row = rows_of(self.stamps_ns, stamps)
            out: IntArray = np.where(row >= 0, new[row], -1)
            return out

        s0, s1 = moved(table.stamp0_ns), moved(table.stamp1_ns)
        keep = (s0 >= 0) & (s1 > s0)
        return replace(table.take(np.flatnonzero(keep)), stamp0_ns=s0[keep], stamp1_ns=s1[keep])

    def use_pairing(self, pairing: str) -> None:
        """Measure from now on with the frames stamped under ``pairing`` (frames without a row left out)."""
        new = self.alternatives.pop(pairing)
        self.alternatives[self.pairing] = self.stamps_ns
        self.pairing, self.stamps_ns = pairing, new
        self.tracks = _without_rows(self.tracks, new)


def _without_rows(tracks: FeatureTracks, stamps: IntArray) -> FeatureTracks:
    """The tracks of frames whose stamp is known (>= 0), in their stamps' order (a pairing may reorder none)."""
    keep = np.flatnonzero(stamps[tracks.rows] >= 0)
    segment = tracks.segment[keep] if tracks.segment.size == len(tracks.ids) else tracks.segment
    return FeatureTracks(rows=tracks.rows[keep], ids=tuple(tracks.ids[k] for k in keep),
                         pixels=tuple(tracks.pixels[k] for k in keep), fixed=tracks.fixed, repeats=tracks.repeats,
                         segment=segment)


def _repeat_notes(frames: CameraFrames, tracks: FeatureTracks) -> list[str]:
    """How many frames repeat the previous one: pixel for pixel, or with no feature moving between them."""
    repeated = frames.duplicate.copy() if frames.duplicate.size else np.zeros(len(frames), dtype=bool)
    repeated[tracks.repeats] = True
    if not repeated.any():
        return []
    numbers = frames.positions[repeated] if frames.positions.size else np.flatnonzero(repeated)
    first = ", ".join(str(int(i)) for i in numbers[:8]) + (", ..." if numbers.size > 8 else "")
    return [f"camera {frames.frame}: {int(repeated.sum())} of {len(frames)} frames duplicated (a repeat of the "
            f"previous frame: the same pixels, or no feature moved): frame {first}"]


def image_cameras(timeline: Timeline) -> list[str]:
    """The camera frames of ``timeline`` with images whose pixels can be had, in order of appearance."""
    images = timeline.image_frames
    return [str(f) for f in dict.fromkeys(images.frame.tolist()) if camera_image_rows(images, str(f)).size]


def camera_motion_source(timeline: Timeline, camera: str, *, max_frames: int = 600, window: int = 150,
                         options: EgoMotionOptions | None = None) -> ImageMotion:
    """Camera ``camera``'s frames decoded (at most ``max_frames``) and tracked, ready to be measured."""
    frames = camera_frames(timeline.image_frames, camera, max_frames=max_frames, window=window)
    intrinsics, known = _intrinsics(timeline, camera, frames.images.shape)
    clock, alternatives = _video_clock(timeline, frames)
    return ImageMotion(frames, camera_tracks(frames, options), intrinsics, intrinsics_known=known, options=options,
                       pairing=str(clock.get("pairing", "")), forced=bool(clock.get("forced", False)),
                       alternatives=alternatives)


def _video_clock(timeline: Timeline, frames: CameraFrames) -> tuple[Mapping[str, Any], dict[str, IntArray]]:
    """The clock pairing the camera's video frames with the rows (a LeRobot episode's), and the frames' stamps
    under the other pairings; nothing for images stamped on their own."""
    cameras = timeline.metadata.get("cameras")
    entry = next((c for c in cameras.values() if isinstance(c, Mapping) and c.get("frame") == frames.frame),
                 None) if isinstance(cameras, Mapping) else None
    clock = entry.get("clock") if entry is not None else None
    images = timeline.image_frames
    if not isinstance(clock, Mapping) or not len(frames):
        return {}, {}
    rows = camera_image_rows(images, frames.frame)
    offset = float((entry or {}).get("timing", {}).get("offset_s") or 0.0)
    alternatives = alternative_stamps(clock, str(images.video_path[frames.rows[0]]),
                                      images.video_time_ns[frames.rows], np.sort(images.log_time_ns[rows]), offset)
    return clock, alternatives


def _intrinsics(timeline: Timeline, camera: str, shape: tuple[int, ...]) -> tuple[Intrinsics, bool]:
    """The camera's model (its first row), or an assumed one from the image size (False)."""
    cams = timeline.cameras
    rows = np.flatnonzero(cams.frame == normalize_frame(camera))
    if rows.size:
        i = int(rows[0])
        k = cams.K[i]
        n = int(cams.n_distortion[i])
        return Intrinsics(fx=float(k[0, 0]), fy=float(k[1, 1]), cx=float(k[0, 2]), cy=float(k[1, 2]),
                          width=int(cams.width[i]), height=int(cams.height[i]),
                          distortion_model=str(cams.distortion_model[i]) if n else "none",
                          distortion=tuple(float(d) for d in cams.distortion[i, :n])), True
    height, width = int(shape[1]), int(shape[2])
    focal = focal_of_fov(width, ASSUMED_FOV_DEG)
    return Intrinsics(fx=focal, fy=focal, cx=(width - 1) / 2, cy=(height - 1) / 2, width=width, height=height,
                      distortion_model="none"), False


def camera_image_rows(images: ImageFrameTable, frame: str) -> IntArray:
    """Rows of ``images`` of camera ``frame`` whose pixels can be had (video, raw, JPEG/PNG), by stamp."""
    name = normalize_frame(frame)
    known = (*RAW_IMAGE_ENCODINGS, *COMPRESSED_IMAGE_ENCODINGS, VIDEO_ENCODING)
    rows = np.flatnonzero((images.frame == name) & np.isin(images.encoding, list(known)))
    out: IntArray = rows[np.argsort(images.stamp_ns[rows], kind="stable")].astype(np.int64)
    return out


def window_rows(count: int, *, max_frames: int, window: int) -> tuple[IntArray, IntArray]:
    """Which of ``count`` frames to decode: all when they fit, else windows of ``window`` consecutive
    frames spread evenly (``max_frames`` in all); returns (positions, window number per position)."""
    if count <= max_frames:
        return np.arange(count, dtype=np.int64), np.zeros(count, dtype=np.int64)
    windows = max(1, max_frames // window)
    starts = np.round(np.linspace(0, count - window, windows)).astype(np.int64)
    positions = (starts[:, None] + np.arange(window)[None, :]).ravel()
    return positions, np.repeat(np.arange(windows, dtype=np.int64), window)


def camera_frames(images: ImageFrameTable, frame: str, *, max_frames: int = 600, window: int = 150) -> CameraFrames:
    """Decode camera ``frame``'s frames (grey), at most ``max_frames`` of them (windows of ``window``)."""
    every = camera_image_rows(images, frame)
    picked, windows = window_rows(every.size, max_frames=max_frames, window=window)
    rows = every[picked]
    notes: list[str] = []
    if picked.size < every.size:
        total = every.size
        notes.append(f"camera {frame}: {total} frames; its motion is measured on {picked.size} of them "
                     f"({windows.max() + 1} runs of {window} consecutive frames spread over the recording)")
    grey, missing, decoded = decode_grey(images, rows)
    duplicate, black = _repeats_and_black(grey, missing)
    for what, flags in (("missing (no frame paired with the row)", missing), ("black", black)):
        if flags.any():
            first = ", ".join(str(int(i)) for i in picked[np.flatnonzero(flags)][:8])
            more = ", ..." if flags.sum() > 8 else ""
            notes.append(f"camera {frame}: {int(flags.sum())} of {rows.size} frames {what}: frame {first}{more}")
    return CameraFrames(frame=normalize_frame(frame), rows=rows, stamps_ns=images.stamp_ns[rows].astype(np.int64),
                        images=grey, usable=~missing & ~duplicate & ~black, window=windows, decoded=decoded,
                        notes=tuple(notes), duplicate=duplicate, positions=picked.astype(np.int64))


def camera_tracks(frames: CameraFrames, options: EgoMotionOptions | None = None) -> FeatureTracks:
    """Feature tracks through each window of usable frames, merged with disjoint ids (rows index ``frames``)."""
    parts: list[FeatureTracks] = []
    starts: list[int] = []
    for w in np.unique(frames.window).tolist():
        sel = np.flatnonzero(frames.window == w)
        # A window is a run of consecutive frames: a slice of them, not a copy of every frame (0.1 s at 640x480).
        run = slice(int(sel[0]), int(sel[-1]) + 1) if sel[-1] - sel[0] + 1 == sel.size else sel
        parts.append(track_features(frames.images[run], usable=frames.usable[run], options=options))
        starts.append(int(sel[0]))
    return _merge(parts, starts)


def _merge(parts: Sequence[FeatureTracks], starts: Sequence[int]) -> FeatureTracks:
    rows: list[IntArray] = []
    ids: list[IntArray] = []
    pixels: list[FloatArray] = []
    fixed: list[IntArray] = []
    repeats: list[IntArray] = []
    segment: list[IntArray] = []
    base = 0
    for number, (part, start) in enumerate(zip(parts, starts, strict=True)):
        rows.append(part.rows + start)
        segment.append(np.full(part.rows.size, number, dtype=np.int64))
        repeats.append(part.repeats + start)
        ids.extend(i + base for i in part.ids)
        pixels.extend(part.pixels)
        fixed.append(part.fixed + base)
        top = max((int(i.max()) for i in part.ids if i.size), default=-1)
        base += max(top, int(part.fixed.max()) if part.fixed.size else -1) + 1

    def joined(arrays: list[IntArray]) -> IntArray:
        return np.concatenate(arrays).astype(np.int64) if arrays else np.zeros(0, dtype=np.int64)

    return FeatureTracks(rows=joined(rows), ids=tuple(ids), pixels=tuple(pixels), fixed=joined(fixed),
                         repeats=joined(repeats), segment=joined(segment))


def decode_grey(images: ImageFrameTable, rows: IntArray) -> tuple[npt.NDArray[np.uint8], BoolArray, int]:
    """Grey pixels of each row (black where missing), the missing rows, and how many frames were decoded."""
    decoded = 0
    encoding = images.encoding[rows]
    video = np.flatnonzero(encoding == VIDEO_ENCODING)
    parts: list[tuple[IntArray, npt.NDArray[np.uint8]]] = []  # positions among ``rows``, their frames
    for path in np.unique(images.video_path[rows[video]]).tolist():
        mine = video[images.video_path[rows[video]] == path]
        got = read_frames(path, images.video_time_ns[rows[mine]], repeat_level=REPEAT_LEVEL)
        decoded += got.decoded
        found = np.flatnonzero(got.image_index >= 0)
        picked = got.image_index[found]
        if found.size:  # the decoded frames themselves when each row has its own, in order (no copy)
            in_order = picked.size == got.images.shape[0] and np.array_equal(picked, np.arange(picked.size))
            parts.append((mine[found], got.images if in_order else got.images.take(picked, axis=0)))
    for i in np.flatnonzero(encoding != VIDEO_ENCODING).tolist():
        still = _still(images, int(rows[i]))
        decoded += 1
        if still is not None:
            parts.append((np.array([i]), still[None]))
    if not parts:
        return np.zeros((rows.size, 1, 1), dtype=np.uint8), np.ones(rows.size, dtype=bool), decoded
    shape = min(parts, key=lambda part: int(part[0][0]))[1].shape[1:]  # the first row's with pixels
    kept = [(where, frames) for where, frames in parts if frames.shape[1:] == shape]
    if len(kept) == 1 and kept[0][0].size == rows.size and kept[0][1].flags.writeable:  # one video for every row
        return kept[0][1], np.zeros(rows.size, dtype=bool), decoded
    stack = np.zeros((rows.size, *shape), dtype=np.uint8)
    missing = np.ones(rows.size, dtype=bool)
    for where, frames in kept:
        stack[where] = frames
        missing[where] = False
    return stack, missing, decoded


def _still(images: ImageFrameTable, row: int) -> npt.NDArray[np.uint8] | None:
    """One raw or JPEG/PNG image as grey (None when it cannot be decoded)."""
    cv2 = require_cv2()
    encoding = str(images.encoding[row])
    if encoding in COMPRESSED_IMAGE_ENCODINGS:
        data = np.frombuffer(images.load(row), dtype=np.uint8)
        out = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
        return None if out is None else np.asarray(out, dtype=np.uint8)
    pixels = images.pixels(row)
    if pixels.dtype != np.uint8:  # 16-bit or float images are depth, not scenery to track
        return None
    if pixels.ndim == 2:
        return np.ascontiguousarray(pixels)
    code = {("rgb8", 3): cv2.COLOR_RGB2GRAY, ("bgr8", 3): cv2.COLOR_BGR2GRAY, ("rgba8", 4): cv2.COLOR_RGBA2GRAY,
            ("bgra8", 4): cv2.COLOR_BGRA2GRAY}.get((encoding, pixels.shape[2]))
    return None if code is None else np.asarray(cv2.cvtColor(pixels, code), dtype=np.uint8)


def _repeats_and_black(grey: npt.NDArray[np.uint8], missing: BoolArray) -> tuple[BoolArray, BoolArray]:
    """Rows repeating the previous present row (within :data:`REPEAT_LEVEL`), and black rows."""
    n = grey.shape[0]
    duplicate = np.zeros(n, dtype=bool)
    present = np.flatnonzero(~missing)
    if present.size > 1:
        duplicate[present[1:]] = mean_abs_differences(grey, present[:-1], present[1:]) <= REPEAT_LEVEL
    black = ~missing & (bright_shares(grey, BLACK_LEVEL) < BLACK_SHARE) if n else np.zeros(0, dtype=bool)
    return duplicate, black
