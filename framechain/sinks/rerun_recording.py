"""A whole recording in Rerun: per camera, its offset in every episode with its interval, its mount's angle from the
recording's, and the episodes that depart.

One recording (``recording_id`` ``"<dataset>: recording"``) on an ``episode`` sequence timeline: for each
camera, ``/recording/<camera>/offset_ms/{offset,low,high}`` (the interval as two lines around the offset),
``/recording/<camera>/mount_deg`` (each episode's mount from the recording's), ``/recording/<camera>/departs``
(a warning at each departing episode, with why) and ``/recording/summary`` (one sentence per camera). Each
episode's own replay is a recording of its own (``<dataset>: episode N``, written by the batch's workers
beside it), so the viewer opened on all of them (``rerun FILE FILE.episodes/*.rrd``) lists the recording
and every episode, as the Rerun docs advise for datasets. The layout is the recording's default blueprint,
and is saved beside it as ``FILE.rbl`` too.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from framechain.analysis.egomotion.recording import CameraRecordingFit
from framechain.sinks.colors import BOUND_COLOR, CORRECTED_COLOR, ERROR_COLOR
from framechain.sinks.fleet_cameras import camera_summary

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb

__all__ = ["EPISODE_TIMELINE", "episode_recordings_dir", "write_recording_view"]

EPISODE_TIMELINE = "episode"


def episode_recordings_dir(path: str | Path) -> Path:
    """Where the episodes' own recordings go beside the recording view ``path`` (``FILE.episodes/``)."""
    out = Path(path)
    return out.with_name(f"{out.name}.episodes")


def write_recording_view(recordings: Mapping[str, Sequence[CameraRecordingFit]], path: str | Path) -> Path:
    """Save every dataset's recording view (one recording per dataset) into one .rrd at ``path``."""
    import rerun as rr

    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream("framechain", recording_id=f"{_name(recordings)}: recording")
    rec.save(out)
    views: list[rrb.ContainerLike] = []
    for log, fits in recordings.items():
        for fit in fits:
            views.append(_log_camera(rec, fit))
        rec.log("/recording/summary", rr.TextDocument("\n\n".join(camera_summary(log, f) for f in fits)),
                static=True)
    blueprint = _blueprint(views)
    rec.send_blueprint(blueprint, make_active=False, make_default=True)
    rec.flush(timeout_sec=60.0)
    rec.disconnect()
    blueprint.save("framechain", out.with_suffix(".rbl"))  # the layout on its own, for a viewer given it by hand
    return out


def _log_camera(rec: rr.RecordingStream, fit: CameraRecordingFit) -> rrb.ContainerLike:
    import rerun as rr
    import rerun.blueprint as rrb

    root = f"/recording/{fit.camera}"
    episodes = np.array([e.episode for e in fit.episodes], dtype=np.int64)
    index = [rr.TimeColumn(EPISODE_TIMELINE, sequence=episodes)]
    offsets = np.array([e.offset_s for e in fit.episodes]) * 1e3
    low = np.array([e.offset_interval_s[0] for e in fit.episodes]) * 1e3
    high = np.array([e.offset_interval_s[1] for e in fit.episodes]) * 1e3
    for name, values, colour, width in (("offset", offsets, CORRECTED_COLOR, 2.0), ("low", low, BOUND_COLOR, 1.0),
                                        ("high", high, BOUND_COLOR, 1.0)):
        rec.log(f"{root}/offset_ms/{name}", rr.SeriesLines(colors=[colour], widths=[width], names=[name]),
                static=True)
        rec.send_columns(f"{root}/offset_ms/{name}", indexes=index, columns=rr.Scalars.columns(scalars=values))
    measured = [e for e in fit.episodes if e.episode in fit.episode_mount_deg]
    if measured:
        rec.log(f"{root}/mount_deg", rr.SeriesPoints(colors=[CORRECTED_COLOR], names=["mount from the recording's"]),
                static=True)
        rec.send_columns(f"{root}/mount_deg", indexes=[rr.TimeColumn(EPISODE_TIMELINE, sequence=[
            e.episode for e in measured])], columns=rr.Scalars.columns(scalars=[
                fit.episode_mount_deg[e.episode] for e in measured]))
    for departure in fit.departures:
        rec.set_time(EPISODE_TIMELINE, sequence=departure.episode)
        rec.log(f"{root}/departs", rr.TextLog(f"episode {departure.episode}: {departure.why}", level="WARN",
                                             color=ERROR_COLOR))
    rec.reset_time()
    plots: list[rrb.View] = [rrb.TimeSeriesView(origin=f"{root}/offset_ms", name=f"{fit.camera}: offset (ms) per "
                                                "episode")]
    if measured:
        plots.append(rrb.TimeSeriesView(origin=f"{root}/mount_deg", name=f"{fit.camera}: mount from the recording's "
                                        "(deg)"))
    if fit.departures:
        plots.append(rrb.TextLogView(origin=f"{root}/departs", name=f"{fit.camera}: departing episodes"))
    return rrb.Horizontal(*plots)


def _blueprint(views: Sequence[rrb.ContainerLike]) -> rrb.Blueprint:
    import rerun.blueprint as rrb

    return rrb.Blueprint(rrb.Vertical(*views, rrb.TextDocumentView(origin="/recording/summary", name="summary")),
                         rrb.TimePanel(state="expanded"), collapse_panels=False)


def _name(recordings: Mapping[str, Sequence[CameraRecordingFit]]) -> str:
    return ", ".join(Path(log).name for log in recordings) or "recording"
