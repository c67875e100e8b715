"""What every part of the Rerun stream shares: its timelines, frame names, colours and options, and
the columns that put rows of observations on the timelines."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray, IntArray
from framechain.replay import ReplayResult
from framechain.sinks.overlay import (
    ImageSelection,
)
from framechain.timeline import PointRole, Timeline

if TYPE_CHECKING:
    import rerun as rr


SENSOR_TIME = "sensor_time"
#: Timeline of the log's receive times.
LOG_TIME = "log_time"
#: Timeline of the observation's row in the ObservationTable.
OBS_INDEX = "obs_index"
#: An episode's timeline: the time since its first row (a duration), in place of ``sensor_time``.
EPISODE_TIME = "episode_time"
#: An episode's wall-clock time, where the dataset stores one.
WALL_TIME = "wall_time"

#: Suffix of the frames that carry the transforms the replay used (``base_link@replay``).
REPLAY_FRAME_SUFFIX = "@replay"
#: Suffix of the pinhole's child frame, as Rerun's own MCAP loader names it.
IMAGE_PLANE_SUFFIX = "_image_plane"

#: framechain's pixels are OpenCV's, (0, 0) at the centre of the top-left pixel; Rerun's 2D space has (0, 0) at
#: that pixel's corner (the image spans (0, 0)..(W, H)). Every pixel drawn over an image is shifted by this.
RERUN_PIXEL_OFFSET = 0.5

@dataclass(frozen=True)
class RerunOptions:
    """Knobs of the Rerun stream."""

    application_id: str = "framechain"
    recording_id: str | None = None
    recording_name: str | None = None
    #: At most this many depth frames are logged (the ones nearest observations, decimated evenly).
    max_images: int = 30
    #: A depth frame within this of an observation stamp is logged with it.
    image_window_ns: int = 50_000_000
    point_radius_m: float = 0.02
    axis_length_m: float = 0.2
    #: Which camera images are logged: near the observations (default), all, or none.
    images: ImageSelection = ImageSelection.NEAR


@dataclass(frozen=True)
class CameraView:
    """One camera's part of a recording: its entity root, its optical frame and its observations (rows of the
    replay). One camera is ``/camera``; each camera of a rig is ``/cameras/<frame>``."""

    root: str
    frame: str
    rows: IntArray
    rig: bool = False

    @property
    def plane(self) -> str:
        return self.frame + IMAGE_PLANE_SUFFIX

    def entity(self, base: str, single: str) -> str:
        """A per-camera entity: ``single`` for one camera, ``<base>/<frame>`` in a rig."""
        return f"{base}/{entity_part(self.frame)}" if self.rig else single


def camera_views(result: ReplayResult, frames: tuple[str, ...]) -> list[CameraView]:
    """The cameras of a recording: the chain's one camera, or every camera of a rig (``frames``)."""
    obs = result.observations
    if len(frames) <= 1:
        return [CameraView("/camera", result.frames.camera, np.arange(len(obs), dtype=np.int64))]
    return [CameraView(f"/cameras/{entity_part(f)}", f, np.flatnonzero(obs.camera_frame == f), rig=True)
            for f in frames]


ROLE_LEAF: dict[PointRole, str] = {
    PointRole.HOP_CAMERA: "camera", PointRole.HOP_BODY: "body", PointRole.HOP_WORLD: "world",
    PointRole.TARGET: "target", PointRole.REFERENCE: "reference",
}


def rerun_pixels(uv: npt.ArrayLike) -> FloatArray:
    """OpenCV pixels (..., 2) in Rerun's 2D image space (see :data:`RERUN_PIXEL_OFFSET`)."""
    out: FloatArray = np.asarray(uv, dtype=float) + RERUN_PIXEL_OFFSET
    return out


def rerun_intrinsics(k: npt.ArrayLike) -> FloatArray:
    """Camera matrices (..., 3, 3) for Rerun's pinhole: the principal point shifted as the pixels are, so the
    ray through an image pixel's centre is the one OpenCV gives that pixel."""
    out: FloatArray = np.array(k, dtype=float)
    out[..., 0, 2] += RERUN_PIXEL_OFFSET
    out[..., 1, 2] += RERUN_PIXEL_OFFSET
    return out


def entity_part(name: str) -> str:
    import rerun as rr

    escaped: str = rr.escape_entity_path_part(name)
    return escaped


def stamp_column(name: str, ns: npt.ArrayLike) -> rr.TimeColumn:
    import rerun as rr

    return rr.TimeColumn(name, timestamp=np.asarray(ns, dtype=np.int64).astype("datetime64[ns]"))


@dataclass(frozen=True)
class Clock:
    """How a run's stamps (integer nanoseconds) become the recording's timelines.

    A robot log: its header stamps on ``sensor_time`` and its receive times on ``log_time``, as dates. An episode
    (a timeline whose metadata holds ``episode_start_ns``: LeRobot stamps are seconds from the episode's start,
    not dates): both as durations from its first row, the stamps on ``episode_time``, and where the dataset
    stores the wall-clock time of that row (``wall_clock_start_ns``), the stamps on ``wall_time`` too.
    """

    stamps: str = SENSOR_TIME
    #: Durations from this stamp (an episode's first row); None: the stamps are dates.
    origin_ns: int | None = None
    #: The wall-clock time (ns since the epoch) at ``origin_ns``, where known.
    wall_origin_ns: int | None = None

    @classmethod
    def of(cls, timeline: Timeline) -> Clock:
        start, wall = timeline.metadata.get("episode_start_ns"), timeline.metadata.get("wall_clock_start_ns")
        if not isinstance(start, int):
            return cls()
        return cls(EPISODE_TIME, start, wall if isinstance(wall, int) else None)

    @property
    def timelines(self) -> tuple[str, ...]:
        """Every timeline the clock writes, the stamps' first."""
        wall = (WALL_TIME,) if self.wall_origin_ns is not None else ()
        return (self.stamps, LOG_TIME, OBS_INDEX, *wall)

    def column(self, name: str, ns: npt.ArrayLike) -> rr.TimeColumn:
        import rerun as rr

        if self.origin_ns is None:
            return stamp_column(name, ns)
        return rr.TimeColumn(name, duration=(np.asarray(ns, dtype=np.int64) - self.origin_ns).astype("timedelta64[ns]"))

    def columns(self, stamp_ns: npt.ArrayLike, log_time_ns: npt.ArrayLike | None = None) -> list[rr.TimeColumn]:
        """The time columns of rows at ``stamp_ns`` (received at ``log_time_ns``)."""
        out = [self.column(self.stamps, stamp_ns)]
        if log_time_ns is not None:
            out.append(self.column(LOG_TIME, log_time_ns))
        if self.wall_origin_ns is not None and self.origin_ns is not None:
            out.append(stamp_column(WALL_TIME, np.asarray(stamp_ns, dtype=np.int64) - self.origin_ns
                                    + self.wall_origin_ns))
        return out

    def obs_indexes(self, result: ReplayResult, rows: IntArray) -> list[rr.TimeColumn]:
        """The time columns of observations ``rows``: their stamps, receive times and row numbers."""
        import rerun as rr

        obs = result.observations
        return [*self.columns(obs.stamp_ns[rows], obs.log_time_ns[rows]),
                rr.TimeColumn(OBS_INDEX, sequence=rows.astype(np.int64))]


def send_per_stamp(rec: rr.RecordingStream, entity: str, result: ReplayResult, clock: Clock, sel: IntArray,
                   columns: Callable[[IntArray], rr.ComponentColumnList]) -> None:
    """One row per observation stamp holding every observation of that stamp (several tags in one
    image): a later row at the same time would hide the earlier ones in the viewer."""
    obs = result.observations
    sel = sel[np.argsort(obs.stamp_ns[sel], kind="stable")]
    starts = np.flatnonzero(np.concatenate([[True], np.diff(obs.stamp_ns[sel]) != 0]))
    lengths = np.diff(np.append(starts, sel.size))
    rec.send_columns(entity, indexes=clock.obs_indexes(result, sel[starts]),
                     columns=columns(sel).partition(lengths=lengths))
