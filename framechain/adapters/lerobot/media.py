"""A camera's frames as a viewer takes them: H.264/H.265 access units (Annex B) remuxed from the mp4, else
each frame as JPEG (or the PNG/JPEG bytes a dataset stored), stamped with the camera's time.

Foxglove's ``CompressedVideo`` wants one access unit per message, Annex B with the parameter sets on
key frames, starting on a key frame, and no B-frames (it does not reorder). An H.264/H.265 stream
that qualifies is remuxed packet for packet (``h264_mp4toannexb`` / ``hevc_mp4toannexb``: nothing is
re-encoded) from the first key frame of the camera's rows; any other (AV1, MPEG-4 Part 2, a stream
with B-frames) is decoded and each row's frame encoded as JPEG. Rows stored as image bytes
(a LeRobot ``image`` feature) keep their bytes.

A frame's stamp is its row's camera stamp; a remuxed packet between rows takes the stamp of the
nearest row shifted by its distance in the file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np

from framechain.adapters.lerobot.video import VideoError, read_frames
from framechain.arrays import IntArray
from framechain.timeline import ImageFrameTable, normalize_frame
from framechain.timeline.frames import COMPRESSED_IMAGE_ENCODINGS

__all__ = ["EncodedFrames", "encoded_frames"]

#: mp4 codec names and their Annex B filter and Foxglove format.
_ANNEXB = {"h264": ("h264_mp4toannexb", "h264"), "hevc": ("hevc_mp4toannexb", "h265")}
JPEG_QUALITY = 90


@dataclass(frozen=True)
class EncodedFrames:
    """One camera's frames, encoded: ``codec`` is ``h264``/``h265`` (access units) or ``jpeg``/``png``."""

    camera: str
    codec: str
    stamps_ns: IntArray
    data: tuple[bytes, ...]
    notes: tuple[str, ...] = field(default=())

    def __len__(self) -> int:
        return len(self.data)


def encoded_frames(images: ImageFrameTable, camera: str) -> EncodedFrames:
    """Camera ``camera``'s frames of ``images`` encoded for a viewer (see the module docstring)."""
    name = normalize_frame(camera)
    rows = np.flatnonzero(images.frame == name)
    rows = rows[np.argsort(images.stamp_ns[rows], kind="stable")]
    stored = rows[np.isin(images.encoding[rows], list(COMPRESSED_IMAGE_ENCODINGS))]
    if stored.size:
        codec = str(images.encoding[stored[0]])
        same = stored[images.encoding[stored] == codec]
        return EncodedFrames(name, codec, images.stamp_ns[same].astype(np.int64),
                             tuple(images.load(int(i)) for i in same))
    video = rows[images.video_frames[rows]]
    if video.size == 0:
        return EncodedFrames(name, "", np.zeros(0, dtype=np.int64), ())
    path = str(images.video_path[video[0]])
    video = video[images.video_path[video] == path]
    remuxed = _remux(path, images.video_time_ns[video], images.stamp_ns[video])
    if isinstance(remuxed, EncodedFrames):
        return EncodedFrames(name, remuxed.codec, remuxed.stamps_ns, remuxed.data)
    return _as_jpeg(name, path, images.video_time_ns[video], images.stamp_ns[video], remuxed)


def _as_jpeg(camera: str, path: str, file_ns: IntArray, stamps_ns: IntArray, why: str) -> EncodedFrames:
    """Each row's frame decoded and encoded as JPEG (rows without a frame are left out)."""
    import cv2

    frames = read_frames(path, file_ns, pixel_format="rgb24")
    keep = np.flatnonzero(frames.image_index >= 0)
    data = []
    for i in keep.tolist():
        ok, buffer = cv2.imencode(".jpg", cv2.cvtColor(frames.image(i), cv2.COLOR_RGB2BGR),
                                  [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        if not ok:
            raise VideoError(path, f"cannot encode frame {i} as JPEG")
        data.append(buffer.tobytes())
    note = f"camera {camera}: frames written as JPEG images ({why})"
    return EncodedFrames(camera, "jpeg", stamps_ns[keep].astype(np.int64), tuple(data), (note,))


def _remux(path: str, file_ns: IntArray, stamps_ns: IntArray) -> EncodedFrames | str:
    """The rows' span of an H.264/H.265 file as Annex B access units, or why it cannot be remuxed."""
    import av

    try:
        container = av.open(path)
    except (OSError, av.FFmpegError) as err:
        raise VideoError(path, f"cannot open video ({err})") from err
    with container:
        stream = container.streams.video[0]
        codec = str(stream.codec_context.name)
        if codec not in _ANNEXB:
            return f"{codec} is not H.264 or H.265"
        start, end = int(file_ns.min()), int(file_ns.max())
        half = round(0.5e9 / float(stream.average_rate or 30))
        base = stream.time_base or Fraction(1, 90_000)
        container.seek(max(int(Fraction(start - half, 1_000_000_000) / base), 0), stream=stream,
                       backward=True, any_frame=False)
        packets = _annexb_packets(container, stream, _ANNEXB[codec][0], start - half, end + half)
        rate = float(stream.average_rate or 30)
    half = round(0.5e9 / rate)
    if not packets:
        return "no key frame among the rows' frames"
    times = np.array([t for t, _ in packets], dtype=np.int64)
    if (np.diff(times) <= 0).any():
        return "the stream has B-frames, which Foxglove does not reorder"
    nearest = np.clip(np.searchsorted(file_ns, times), 0, file_ns.size - 1)
    before = np.clip(nearest - 1, 0, file_ns.size - 1)
    nearest = np.where(np.abs(file_ns[before] - times) < np.abs(file_ns[nearest] - times), before, nearest)
    # A packet of a row takes the row's stamp; one between rows is placed by its distance from the nearest.
    gap = times - file_ns[nearest]
    stamps = stamps_ns[nearest] + np.where(np.abs(gap) < half, 0, gap)
    return EncodedFrames("", _ANNEXB[codec][1], stamps.astype(np.int64), tuple(d for _, d in packets))


def _annexb_packets(container: object, stream: object, bsf_name: str, start_ns: int, end_ns: int
                    ) -> list[tuple[int, bytes]]:
    """(presentation time ns, Annex B bytes) of the packets from the first key frame at or after ``start_ns``."""
    from av.bitstream import BitStreamFilterContext

    bsf = BitStreamFilterContext(bsf_name, stream)  # type: ignore[arg-type]
    out: list[tuple[int, bytes]] = []
    base = stream.time_base  # type: ignore[attr-defined]
    for packet in container.demux(stream):  # type: ignore[attr-defined]
        if packet.pts is None or packet.size == 0:
            continue
        time_ns = round(float(packet.pts * base) * 1e9)
        if time_ns > end_ns:
            break
        if time_ns < start_ns or (not out and not packet.is_keyframe):
            continue
        for filtered in bsf.filter(packet):
            out.append((time_ns, bytes(filtered)))
    return out
