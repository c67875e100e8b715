"""The clock of a LeRobot video: how its frames pair with the episode's rows.

LeRobot's own writer stores ``timestamp = frame_index / fps``, and a row's frame is the one shown at
that time in the file (plus the episode's ``from_timestamp`` in v3.0): pairing **by presentation
time**. Recorders built on other loops store the rows' real capture times instead (a real SO-101
recording: about 18.6 Hz and variable, where info.json says 20 fps) while each video holds exactly
one frame per row, encoded at the nominal rate: frame k belongs to row k, whatever its presentation
time says (pairing **by order**; pairing those rows by time picks frames captured up to a second
away). When neither holds (more or fewer frames than rows, and stamps off ``frame_index / fps``), the
rows' span is mapped linearly onto the frames' span, video time ``= a t + b`` (a **fitted** clock).

:func:`video_clock` decides from the files alone: the frames are counted in the episode's span of
the video (packets demuxed, nothing decoded) and compared with the rows and their stamps; robot.yaml
can force a pairing (``cameras.NAME.timing.pairing``). The cameras' own motion then confirms it
(:mod:`framechain.analysis.egomotion.run`): under the wrong pairing the misfit against forward
kinematics is much larger. :meth:`VideoClock.capture_stamps_ns` gives a frame's capture time under
any pairing, for that comparison.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.adapters.lerobot.video import VideoError
from framechain.arrays import FloatArray, IntArray

__all__ = ["VIDEO_REFERENCE_NUDGE_NS", "Pairing", "VideoClock", "alternative_stamps", "episode_frame_times_s",
           "video_clock"]

#: Video references are nudged this much later than the frame's time: float32 timestamps fall a few ns
#: before the frame's presentation time, and a viewer shows the frame at or before the reference
#: (LeRobot itself accepts frames within 100 us).
VIDEO_REFERENCE_NUDGE_NS = 50_000


class Pairing(StrEnum):
    """How a video's frames pair with the rows."""

    PRESENTATION = "presentation"  # the frame shown at the row's timestamp (LeRobot's convention)
    ORDER = "order"  # frame k with row k (one frame per row, stamps in real time)
    FITTED = "fitted"  # the frame shown at a t + b, the rows' span mapped onto the frames'


#: A row whose timestamp is within this share of a frame period of ``frame_index / fps`` lands on its own
#: frame when paired by presentation time.
ON_FRAME_SHARE = 0.25


@dataclass(frozen=True)
class VideoClock:
    """One video's clock for one episode: the pairing used, why, and what it was decided from.

    ``frame_times_s`` are the presentation times of the episode's frames in the file (sorted; from the
    file's start); ``scale`` and ``shift_s`` map a row's timestamp ``t`` to its frame's time in the
    file under the fitted clock, ``from_s + shift_s + scale * t``.
    """

    key: str
    pairing: Pairing
    forced: bool
    rows: int
    frames: int
    declared_fps: float
    stamp_rate_hz: float
    max_departure_s: float
    from_s: float
    frame_times_s: FloatArray
    scale: float = 1.0
    shift_s: float = 0.0
    to_s: float | None = None

    def file_times_ns(self, timestamp_s: npt.ArrayLike, pairing: Pairing | None = None) -> IntArray:
        """Each row's frame time in the file (ns) under ``pairing`` (default: the clock's own).

        By order, rows past the last frame get the time of none (-1): they have no frame.
        """
        t = np.asarray(timestamp_s, dtype=np.float64)
        how = pairing or self.pairing
        if how is Pairing.ORDER:
            out = np.full(t.size, -1, dtype=np.int64)
            k = min(t.size, self.frame_times_s.size)
            out[:k] = np.round(self.frame_times_s[:k] * 1e9).astype(np.int64)
            return out
        times = self.from_s + self.shift_s + self.scale * t if how is Pairing.FITTED else self.from_s + t
        result: IntArray = np.round(times * 1e9).astype(np.int64)
        return result

    def capture_stamps_ns(self, file_time_ns: npt.ArrayLike, timestamp_s: npt.ArrayLike,
                          pairing: Pairing) -> IntArray:
        """When each frame (by its time in the file) was captured under ``pairing``, in the rows' time (ns).

        By presentation time a frame was captured at its own presentation time; by order at the
        timestamp of the row of its rank; by the fitted clock at the timestamp the map sends to it.
        -1 where the pairing gives the frame no row.
        """
        v = np.asarray(file_time_ns, dtype=np.int64) * 1e-9
        t = np.asarray(timestamp_s, dtype=np.float64)
        if pairing is Pairing.ORDER:
            rank = np.clip(np.searchsorted(self.frame_times_s, v - 0.5 / max(self.declared_fps, 1.0)), 0,
                           max(self.frame_times_s.size - 1, 0))
            row = np.round(t[np.minimum(rank, t.size - 1)] * 1e9)
            out: IntArray = np.where(rank < t.size, row, -1).astype(np.int64)
            return out
        captured = (v - self.from_s - self.shift_s) / self.scale if pairing is Pairing.FITTED else v - self.from_s
        result: IntArray = np.round(captured * 1e9).astype(np.int64)
        return result

    @property
    def why(self) -> str:
        """Why this pairing, in words: frames against rows, declared fps against the stamps' rate."""
        rates = f"info.json {self.declared_fps:g} fps, stamps {self.stamp_rate_hz:.1f} Hz"
        departs = f"timestamps depart from frame_index / fps by up to {self.max_departure_s:.3f} s"
        counts = f"{self.frames} frames for {self.rows} rows"
        if self.forced:
            return f"forced in robot.yaml ({counts}; {rates}; {departs})"
        if self.pairing is Pairing.PRESENTATION:
            return f"timestamps are frame_index / fps, LeRobot's convention ({counts}; {rates})"
        if self.pairing is Pairing.ORDER:
            return f"one frame per row: {counts}, {departs} ({rates})"
        return (f"{counts} and {departs} ({rates}): the rows' span mapped onto the frames', video time "
                f"= {self.scale:.4f} t {'+' if self.shift_s >= 0 else '-'} {abs(self.shift_s):.3f} s")

    def summary(self) -> str:
        """One line: which pairing and why."""
        return f"video {self.key}: frames paired with rows by {self.pairing.value}: {self.why}"

    def to_json(self) -> dict[str, Any]:
        return {"key": self.key, "pairing": self.pairing.value, "forced": self.forced, "rows": self.rows,
                "frames": self.frames, "declared_fps": self.declared_fps,
                "stamp_rate_hz": round(self.stamp_rate_hz, 4), "max_departure_s": round(self.max_departure_s, 6),
                "from_s": self.from_s, "to_s": self.to_s, "scale": round(self.scale, 9),
                "shift_s": round(self.shift_s, 9), "why": self.why}


def episode_frame_times_s(path: str | Path, from_s: float = 0.0, to_s: float | None = None) -> FloatArray:
    """Presentation times (s from the file's start) of the frames in ``[from_s, to_s)``, demuxed, not decoded."""
    import av

    try:
        container = av.open(str(path))
    except (OSError, av.FFmpegError) as err:
        raise VideoError(path, f"cannot open video ({err})") from err
    with container:
        if not container.streams.video:
            raise VideoError(path, "holds no video stream")
        stream = container.streams.video[0]
        base = stream.time_base or Fraction(1, 90_000)
        rate = float(stream.average_rate or stream.guessed_rate or 30)
        eps = 0.25 / rate
        if from_s > 0:
            container.seek(max(int(Fraction(from_s) / base) - 1, 0), stream=stream, backward=True, any_frame=False)
        times: list[float] = []
        try:
            for packet in container.demux(stream):
                if packet.pts is None or packet.size == 0:
                    continue
                time = float(packet.pts * base)
                if to_s is not None and packet.dts is not None and float(packet.dts * base) > to_s + 1.0:
                    break
                if time >= from_s - eps and (to_s is None or time < to_s - eps):
                    times.append(time)
        except (OSError, ValueError) as err:  # av's errors derive from these
            raise VideoError(path, f"cannot demux video ({err})") from err
    out: FloatArray = np.unique(np.asarray(times, dtype=np.float64))
    return out


def video_clock(
    key: str, frame_times_s: FloatArray, timestamp_s: npt.ArrayLike, frame_index: npt.ArrayLike, *,
    fps: float, from_s: float = 0.0, to_s: float | None = None, forced: str | None = None,
) -> VideoClock:
    """The pairing of one episode's video (its frames' times ``frame_times_s`` in the file) with its rows.

    By presentation time when every row's timestamp lands on its own frame (within a quarter of a
    frame period of ``frame_index / fps``); by order when the video has exactly one frame per row;
    else a fitted clock. ``forced`` (robot.yaml's ``timing.pairing``) overrides the choice.
    """
    t = np.asarray(timestamp_s, dtype=np.float64)
    index = np.asarray(frame_index, dtype=np.float64)
    departure = float(np.abs(t - index / fps).max()) if t.size else 0.0
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    rate = (t.size - 1) / span if span > 0 else float(fps)
    frames = np.asarray(frame_times_s, dtype=np.float64)
    if departure <= ON_FRAME_SHARE / fps:
        found = Pairing.PRESENTATION
    elif frames.size == t.size:
        found = Pairing.ORDER
    else:
        found = Pairing.FITTED
    pairing = Pairing(forced) if forced else found
    scale, shift = _fitted_map(t, frames, from_s)
    return VideoClock(key=key, pairing=pairing, forced=forced is not None, rows=int(t.size), frames=int(frames.size),
                      declared_fps=float(fps), stamp_rate_hz=float(rate), max_departure_s=departure, from_s=from_s,
                      frame_times_s=frames, scale=scale, shift_s=shift, to_s=to_s)


def _fitted_map(t: FloatArray, frames: FloatArray, from_s: float) -> tuple[float, float]:
    """``a`` and ``b`` of video time ``= from + b + a t`` sending the first and last rows to the first and last
    frames (identity when either has fewer than two)."""
    if t.size < 2 or frames.size < 2 or t[-1] <= t[0]:
        return 1.0, 0.0
    scale = float((frames[-1] - frames[0]) / (t[-1] - t[0]))
    return scale, float(frames[0] - from_s - scale * t[0])


def alternative_stamps(clock: Mapping[str, Any], video_path: str, file_time_ns: npt.ArrayLike,
                       row_stamps_ns: npt.ArrayLike, offset_s: float = 0.0) -> dict[str, IntArray]:
    """Each frame's capture time (ns, ``offset_s`` added as the camera's stamps have it) under every other
    pairing than ``clock``'s (its JSON, as :meth:`VideoClock.to_json` writes it in an episode's metadata).

    ``file_time_ns`` are the frames' references into ``video_path`` (nudged as the reader writes them),
    ``row_stamps_ns`` the episode's rows' timestamps in order. -1 where a pairing gives a frame no row.
    """
    rows = np.asarray(row_stamps_ns, dtype=np.int64) * 1e-9
    to_s = clock.get("to_s")
    own = video_clock(str(clock["key"]), episode_frame_times_s(video_path, float(clock["from_s"]),
                                                               None if to_s is None else float(to_s)),
                      rows, np.arange(rows.size), fps=float(clock["declared_fps"]), from_s=float(clock["from_s"]),
                      forced=str(clock["pairing"]))
    times = np.asarray(file_time_ns, dtype=np.int64) - VIDEO_REFERENCE_NUDGE_NS
    out: dict[str, IntArray] = {}
    for pairing in Pairing:
        if pairing is own.pairing:
            continue
        stamps = own.capture_stamps_ns(times, rows, pairing)
        out[pairing.value] = np.where(stamps >= 0, stamps + round(offset_s * 1e9), -1).astype(np.int64)
    return out
