"""The recording-level fit of a batch: each LeRobot dataset's cameras fitted across its episodes.

Each episode is a work unit (on a pool or Ray); its record keeps what its cameras' fits rest on
(``cameras``: link, offset and interval, mount, the sums the mount rests on, every candidate's misfit).
Once the records are gathered, :func:`recording_fits` combines them per dataset
(:func:`framechain.analysis.egomotion.recording.fit_recording`), and :func:`write_recordings` writes
``recording.json`` (per dataset and camera: link, mount and its interval, unobservable axes, each
episode's offset, the episodes that depart and why) and ``fleet_cameras.parquet`` (one row per
episode and camera: offset and interval, the episode's link, its mount's angle from the recording's,
and whether it departs).
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from framechain.analysis.egomotion.recording import CameraRecordingFit, EpisodeCamera, fit_recording
from framechain.files import write_atomically

__all__ = ["CAMERAS_TABLE", "CAMERA_SCHEMA", "RECORDING_JSON", "camera_table", "recording_fits", "write_recordings"]

RECORDING_JSON = "recording.json"
CAMERAS_TABLE = "fleet_cameras.parquet"

CAMERA_SCHEMA = pa.schema([
    ("log", pa.string()),
    ("episode", pa.int64()),
    ("camera", pa.string()),
    ("name", pa.string()),
    ("link", pa.string()),  # the episode's own fit
    ("recording_link", pa.string()),
    ("offset_s", pa.float64()),
    ("offset_low_s", pa.float64()),
    ("offset_high_s", pa.float64()),
    ("mount_from_recording_deg", pa.float64()),  # null: another link, or not explained
    ("explained", pa.bool_()),
    ("departs", pa.bool_()),
    ("why", pa.string()),
])


def recording_fits(records: Sequence[Mapping[str, Any]], *, seed: int = 0) -> dict[str, tuple[CameraRecordingFit, ...]]:
    """Per dataset (its path) with measured cameras in at least one episode, each camera's recording-level fit."""
    by_log: dict[str, list[EpisodeCamera]] = {}
    episodes: dict[str, list[Mapping[str, Any]]] = {}
    for record in records:
        episode = record.get("episode")
        if episode is None:
            continue
        episodes.setdefault(str(record["log"]), []).append(record)
        for entry in record.get("cameras") or ():
            camera = EpisodeCamera.from_entry(int(episode), entry)
            if camera is not None:
                by_log.setdefault(str(record["log"]), []).append(camera)
    return {log: tuple(replace(fit, left_out=_left_out(fit, episodes[log]))
                       for fit in fit_recording(cameras, seed=seed)) for log, cameras in by_log.items()}


def _left_out(fit: CameraRecordingFit, records: Sequence[Mapping[str, Any]]) -> tuple[tuple[int, str], ...]:
    """The episodes of the recording that gave ``fit``'s camera no measurement, each with why: the episode's own
    reason for the camera, its error, or a note of its naming the camera (a video missing)."""
    measured = {e.episode for e in fit.episodes}
    out = []
    for record in sorted(records, key=lambda r: int(r["episode"])):
        episode = int(record["episode"])
        if episode in measured:
            continue
        said = [c["why"] for c in record.get("cameras_left_out") or () if c.get("camera") == fit.camera]
        named = [n for n in record.get("notes") or () if _names(n, fit.camera) or (fit.name and _names(n, fit.name))]
        failed = [str(record["error"])] if record.get("error") else []
        out.append((episode, next(iter([*said, *failed, *named]),
                                  f"no measurement of it in this episode (status {record.get('status')})")))
    return tuple(out)


def _names(note: str, camera: str) -> bool:
    """``note`` is about ``camera``: "camera NAME" not followed by more of a name (``wrist`` is not ``wrist2``)."""
    return re.search(rf"\bcamera {re.escape(camera)}(?![\w-])", note) is not None


def camera_table(fits: Mapping[str, Sequence[CameraRecordingFit]]) -> pa.Table:
    """One row per episode and camera (schema :data:`CAMERA_SCHEMA`)."""
    rows = []
    for log, cameras in fits.items():
        for fit in cameras:
            recording_link = fit.link if fit.explained else None  # no episode explained: no link for the recording
            why: dict[int, list[str]] = {}
            for departure in fit.departures:
                why.setdefault(departure.episode, []).append(departure.why)
            for e in fit.episodes:
                rows.append({
                    "log": log, "episode": e.episode, "camera": e.camera, "name": e.name, "link": e.link,
                    "recording_link": recording_link, "offset_s": e.offset_s,
                    "offset_low_s": e.offset_interval_s[0], "offset_high_s": e.offset_interval_s[1],
                    "mount_from_recording_deg": fit.episode_mount_deg.get(e.episode), "explained": e.explained,
                    "departs": e.episode in why, "why": "; ".join(why.get(e.episode, [])) or None,
                })
            # An episode that measured nothing of the camera is a row too, with why (the counts reconcile).
            rows.extend({"log": log, "episode": episode, "camera": fit.camera, "name": fit.name, "link": None,
                         "recording_link": recording_link, "offset_s": None, "offset_low_s": None,
                         "offset_high_s": None,
                         "mount_from_recording_deg": None, "explained": None, "departs": False,
                         "why": f"left out: {reason}"} for episode, reason in fit.left_out)
    return pa.Table.from_pylist(rows, schema=CAMERA_SCHEMA)


def write_recordings(fits: Mapping[str, Sequence[CameraRecordingFit]], out_dir: str | Path) -> dict[str, Path]:
    """recording.json and fleet_cameras.parquet in ``out_dir`` (nothing when no dataset's camera was measured)."""
    if not fits:
        return {}
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    document = {"schema": "framechain/recording@1",
                "recordings": [{"log": log, "cameras": [fit.to_json() for fit in cameras]}
                               for log, cameras in fits.items()]}
    paths = {"recording": out / RECORDING_JSON, "cameras": out / CAMERAS_TABLE}
    write_atomically(paths["recording"], lambda tmp: tmp.write_text(json.dumps(document, indent=1)))
    write_atomically(paths["cameras"], lambda tmp: pq.write_table(camera_table(fits), tmp))
    return paths


