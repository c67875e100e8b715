"""Stream one replay to Rerun 0.41: the frame tree, the camera, every hop's point, errors, findings.

What the recording holds (entity paths; frames are Rerun named frames, TF style):

- ``/tf/<child>``: the log's frame tree, one entity per child frame, ``Transform3D`` with
  ``parent_frame``/``child_frame`` (``T_parent_child``); static edges once as static data,
  dynamic edges in bulk at their header stamps.
- ``/frames/<frame>``: axes and the name of every frame (static); ``/frames/replay/<frame>`` for
  the replay's frames below.
- ``/replay/world_from_body`` and ``/replay/body_from_cam``: the transforms the replay actually
  used for each observation, at that observation's time, between the world frame and the
  frames ``<body>@replay`` and ``<camera>@replay``. Rerun resolves transforms at the cursor
  without interpolation; these make the hop points land where the replay put them.
- ``/camera``: the chain camera as a ``Pinhole`` (RDF) under its optical frame, with the child
  frame ``<camera>_image_plane``; ``/camera/depth`` the depth frames nearest the observations
  (decimated); ``/camera/detections`` every observation's pixel as a 2D point (the pixel framechain used;
  ``/camera/overlay/detector_centre`` the centre a tag's detector logged where framechain used its own).
  Every pixel drawn over an image is shifted by +0.5 from framechain's (OpenCV's) convention into
  Rerun's, where (0, 0) is the top-left pixel's corner; the pinhole's principal point likewise.
- ``/camera/image``: the camera's images (``--images near``: those nearest the observations; ``all``;
  ``none``): ``Image`` for raw encodings, ``EncodedImage`` for JPEG/PNG (never decoded here);
  ``/camera/video``: a LeRobot episode's mp4 as ``AssetVideo`` and one ``VideoFrameReference`` per
  frame (decoded by the viewer).
- ``/camera/overlay/*``: the chain drawn on the image (:mod:`framechain.sinks.overlay`): ``corners``
  (fiducial quads), ``recomputed`` and ``as_run`` (the world points projected back through the
  replay's transforms), ``error`` (a line between them, coloured by the finding that explains it);
  ``/series/error_px/as_run`` the length of that line.
- ``/points/recomputed/{camera,body,world}``: the replay's point at every hop, in the hop's frame;
  ``/points/as_run/{camera,body,world,target}``: the robot's own logged points as the attribution
  aligned them (:mod:`framechain.analysis.evidence.alignment`: matched to observations, in the hop's
  frame); ``/points/reference``: reference truth; ``/points/error/<hop>``: arrows from recomputed
  to as-run.
- ``/series/error_mm/<hop>`` (recomputed vs as-run, and ``target``/``reference``) and
  ``/series/gap_ms/<hop>`` (observation stamp minus the stamp of the transform sample used):
  ``Scalars``, one row per replayed observation.
- ``/log/findings``, ``/log/rejected``, ``/log/stale``: ``TextLog`` entries (``/log/verdict`` instead of
  findings: why there are none, e.g. nothing could be checked); ``/summary``: a Markdown ``TextDocument``
  with the counts, the findings and the colour legend.

Timelines: ``sensor_time`` (header stamps), ``log_time`` (receive time in the log), and
``obs_index`` (row of the observation) on everything tied to an observation. Rerun's own
wall-clock ``log_time`` is switched off so the name means the log's receive time. An episode
(LeRobot: stamps in seconds from its start) has ``episode_time`` in place of ``sensor_time``, and
``log_time``, as durations from its first row, plus ``wall_time`` where the dataset stores the
wall-clock (:class:`~framechain.sinks.rerun_common.Clock`).

The default blueprint is sent once everything is logged, made of the views that have data
(:func:`~framechain.sinks.rerun_blueprint.default_blueprint`): an episode without detections shows
its cameras, its frame tree in 3D, one rotation-rate plot per camera and the text, nothing empty.
In 3D only the chain's frames are named (chain frames at one place share a label); every other
label (points, arrows, lines) shows on hover.

Everything per observation goes through ``send_columns`` (one call per entity, never one call per
observation per hop).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from framechain.analysis.run import Run
from framechain.arrays import FloatArray
from framechain.errors import FramechainError
from framechain.sinks.colors import REFERENCE_COLOR
from framechain.sinks.overlay import ImageOverlay, ImageSelection, image_overlay
from framechain.sinks.rerun_blueprint import default_blueprint, image_view_bounds
from framechain.sinks.rerun_checks import curve_entity, curve_title, log_checks
from framechain.sinks.rerun_common import (
    EPISODE_TIME,
    LOG_TIME,
    OBS_INDEX,
    ROLE_LEAF,
    SENSOR_TIME,
    WALL_TIME,
    Clock,
    RerunOptions,
    camera_views,
)
from framechain.sinks.rerun_egomotion import camera_root, log_camera_motion, log_camera_videos
from framechain.sinks.rerun_rig import log_rig
from framechain.sinks.rerun_scene import (
    log_camera,
    log_detections,
    log_frame_tree,
    log_images,
    log_overlay,
    log_used_transforms,
)
from framechain.sinks.rerun_series import (
    log_explained_error,
    log_points,
    log_series,
    log_text,
    summary_markdown,
)
from framechain.sinks.text import FindingView, measured_instead
from framechain.timeline import Timeline

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb


class RerunSinkError(FramechainError):
    """The recording could not be written or sent (unreachable viewer, unwritable file)."""


class OutputMode(StrEnum):
    """Where the recording goes."""

    SAVE = "save"  # an .rrd file; needs no viewer
    CONNECT = "connect"  # a running viewer (or server) at a gRPC URL
    SPAWN = "spawn"  # start a local viewer; falls back to SAVE without a display


@dataclass(frozen=True)
class RerunTarget:
    """One output: ``path`` for SAVE (and the fallback of SPAWN), ``url`` for CONNECT."""

    mode: OutputMode
    path: Path | None = None
    url: str | None = None

    @classmethod
    def save(cls, path: str | Path) -> RerunTarget:
        return cls(OutputMode.SAVE, path=Path(path))

    @classmethod
    def connect(cls, url: str | None = None) -> RerunTarget:
        """``url`` like ``rerun+http://127.0.0.1:9876/proxy`` (None: Rerun's default local viewer)."""
        return cls(OutputMode.CONNECT, url=url)

    @classmethod
    def spawn(cls, fallback_path: str | Path) -> RerunTarget:
        """A local viewer; ``fallback_path`` is where the recording is saved when none can start."""
        return cls(OutputMode.SPAWN, path=Path(fallback_path))


@dataclass(frozen=True)
class RerunOutcome:
    """What was written: the output actually used, notes for the user, and rows per entity."""

    mode: OutputMode
    path: Path | None
    url: str | None
    fell_back: bool
    notes: tuple[str, ...]
    rows: Mapping[str, int]


# ----------------------------------------------------------------------------------------------
# Output selection


def display_available(env: Mapping[str, str] | None = None) -> bool:
    """Whether a local viewer could open a window (``DISPLAY`` or ``WAYLAND_DISPLAY`` is set)."""
    e = os.environ if env is None else env
    return bool(e.get("DISPLAY") or e.get("WAYLAND_DISPLAY"))


def resolve_target(target: RerunTarget, *, env: Mapping[str, str] | None = None) -> tuple[RerunTarget, str | None]:
    """The output to use: SPAWN without a display becomes SAVE to its fallback path, with a note."""
    if target.mode is OutputMode.SPAWN and not display_available(env):
        path = target.path or Path("framechain.rrd")
        note = (f"no display (DISPLAY and WAYLAND_DISPLAY are unset): the Rerun viewer cannot start; "
                f"saving to {path} instead (open it with `rerun {path}`)")
        return RerunTarget.save(path), note
    if target.mode is OutputMode.SAVE and target.path is None:
        raise RerunSinkError("saving a recording needs a path")
    return target, None


#: Observations spanning less than this are one moment: the series show this much either side of it.
SHORT_LOG_NS = 1_000_000_000

#: Where ``connect_grpc(None)`` sends: Rerun's default local viewer.
DEFAULT_GRPC_URL = "rerun+http://127.0.0.1:9876/proxy"


def _check_listening(url: str | None, *, timeout_s: float = 2.0) -> None:
    """Fail at once when nothing listens at the URL's host and port.

    Rerun's client otherwise retries for about 11 s before its flush fails.
    """
    import socket
    from urllib.parse import urlsplit

    full = url or DEFAULT_GRPC_URL
    try:
        parts = urlsplit(full)
        host = parts.hostname
        port = parts.port or (443 if parts.scheme.endswith("https") else 9876)
    except ValueError as err:
        raise RerunSinkError(f"not a Rerun gRPC URL: {full!r} (expected rerun+http://HOST:PORT/proxy)") from err
    if not parts.scheme.startswith("rerun") or not host:
        raise RerunSinkError(f"not a Rerun gRPC URL: {full!r} (expected rerun+http://HOST:PORT/proxy)")
    try:
        with socket.create_connection((host, port), timeout=timeout_s):
            pass
    except OSError as err:
        raise RerunSinkError(
            f"no Rerun viewer listening at {full} ({err.strerror or err}); start one with `rerun` "
            "or use --save FILE.rrd"
        ) from err


# ----------------------------------------------------------------------------------------------
# Public entry points


def stream_replay(
    run: Run,
    target: RerunTarget,
    *,
    options: RerunOptions | None = None,
    env: Mapping[str, str] | None = None,
    notify: Callable[[str], None] | None = None,
) -> RerunOutcome:
    """Send one run to ``target`` (save, connect or spawn), with the default blueprint.

    Draws the run's replay, the evidence its stages aligned, its findings and the chain's declared
    reference point. ``notify`` receives notes for the user (default: stderr), such as the fallback
    from spawn to save. Ends with flush and disconnect (which writes the RRD footer).
    """
    import rerun as rr

    opts = options or RerunOptions()
    say = notify or _stderr
    chosen, note = resolve_target(target, env=env)
    notes: list[str] = [note] if note else []
    if note:
        say(note)
    rec = rr.RecordingStream(opts.application_id, recording_id=opts.recording_id)
    overlay = image_overlay(run.timeline, run.replay, run.aligned, run.findings)
    fell_back = chosen.mode is not target.mode
    try:
        if chosen.mode is OutputMode.SAVE:
            assert chosen.path is not None
            chosen.path.parent.mkdir(parents=True, exist_ok=True)
            rec.save(chosen.path)
        elif chosen.mode is OutputMode.CONNECT:
            _check_listening(chosen.url)
            rec.connect_grpc(chosen.url)
        else:
            try:
                rec.spawn()
            except RuntimeError as err:  # no `rerun` executable on PATH
                path = chosen.path or Path("framechain.rrd")
                msg = f"cannot start the Rerun viewer ({err}); saving to {path} instead"
                notes.append(msg)
                say(msg)
                chosen = RerunTarget.save(path)
                fell_back = True
                rec.save(path)
        clock = Clock.of(run.timeline)
        rows = _log_run(rec, run, overlay, opts, clock)
        # The layout follows what was logged: a view is there only when it has data.
        rec.send_blueprint(_blueprint(run, rows, overlay, clock), make_active=False, make_default=True)
        rec.flush(timeout_sec=60.0)
        rec.disconnect()
    except (RuntimeError, OSError) as err:
        where = str(chosen.path) if chosen.mode is OutputMode.SAVE else (chosen.url or "the default viewer")
        raise RerunSinkError(f"Rerun {chosen.mode.value} to {where} failed: {err}") from err
    finally:
        del rec
        _release_dropped_recordings()
    return RerunOutcome(
        mode=chosen.mode, path=chosen.path if chosen.mode is OutputMode.SAVE else None,
        url=chosen.url, fell_back=fell_back, notes=tuple(notes), rows=rows,
    )


def _image_box(timeline: Timeline, frame: str) -> tuple[float, float, float, float] | None:
    """(u_min, u_max, v_min, v_max) of a camera's whole image (None without a camera model)."""
    rows = np.flatnonzero(timeline.cameras.frame == frame)
    if rows.size == 0:
        return None
    width, height = float(timeline.cameras.width[rows[0]]), float(timeline.cameras.height[rows[0]])
    return 0.0, width, 0.0, height


def _release_dropped_recordings() -> None:
    """Stop the threads of recordings Python no longer holds.

    Rerun 0.41 keeps two threads per RecordingStream alive after ``disconnect`` until its orphan
    sweep runs (normally at exit): a process that replays many logs (a notebook, a fleet worker,
    the fuzzer) would otherwise run out of threads.
    """
    import rerun_bindings

    sweep = getattr(rerun_bindings, "flush_and_cleanup_orphaned_recordings", None)
    if sweep is not None:
        sweep()


def log_replay(rec: rr.RecordingStream, run: Run, *, options: RerunOptions | None = None,
               clock: Clock | None = None) -> dict[str, int]:
    """Log everything of one run to an open recording; returns rows logged per entity path (what the run's
    default layout shows). ``clock``: how stamps become timelines (default: the run's own, an
    episode's durations from its first row).

    The caller owns ``rec`` (its sink, flush and disconnect), so this also serves notebooks
    (``rec.notebook_show()``), in-memory recordings, and recordings of many runs (one per episode).
    """
    return _log_run(rec, run, image_overlay(run.timeline, run.replay, run.aligned, run.findings),
                    options or RerunOptions(), clock or Clock.of(run.timeline))


def _blueprint(run: Run, logged: Mapping[str, int], overlay: ImageOverlay, clock: Clock) -> rrb.Blueprint:
    """The default layout of a run's recording: the views that have data in it (``logged``: rows per entity path)
    for this kind of run (a robot log, a rig, an episode)."""
    views = camera_views(run.replay, run.chain.camera_frames() if run.chain.is_rig else ())
    cameras = [(v.frame, v.root, _image_box(run.timeline, v.frame) if v.rig else image_view_bounds(overlay))
               for v in views]
    shown = {v.frame for v in views}
    cameras += [(frame, camera_root(frame), None) for frame in dict.fromkeys(run.timeline.cameras.frame.tolist())
                if frame not in shown]
    curves = [(curve_entity(c), curve_title(c)) for c in run.attribution.curves] if run.attribution else []
    stamps = run.replay.observations.stamp_ns
    # A log of one moment (one image): the series' time axes would span months around it.
    moment = stamps.size > 0 and int(stamps.max() - stamps.min()) < SHORT_LOG_NS
    return default_blueprint(run.replay.frames, logged, cameras=cameras,
                             curves=curves, window_s=SHORT_LOG_NS / 1e9 if moment else None, timelines=clock.timelines)


def _log_run(rec: rr.RecordingStream, run: Run, overlay: ImageOverlay, opts: RerunOptions,
             clock: Clock) -> dict[str, int]:
    import rerun as rr

    result, timeline = run.replay, run.timeline
    if len(run.aligned) != len(result.observations) or not np.array_equal(run.aligned.obs_id,
                                                                          result.observations.obs_id):
        raise RerunSinkError("the aligned evidence is not that of this replay's observations")
    rr.set_log_time_enabled(False, recording=rec)
    rr.set_log_tick_enabled(False, recording=rec)
    if opts.recording_name:
        rec.send_recording_name(opts.recording_name)
    rows: dict[str, int] = {}
    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    views = camera_views(result, run.chain.camera_frames() if run.chain.is_rig else ())
    log_frame_tree(rec, timeline, clock, result.frames, opts, rows, tuple(v.frame for v in views),
                   replayed=bool(result.replayed.any()))
    log_used_transforms(rec, result, clock, views, rows)
    for view in views:
        log_camera(rec, timeline, result, clock, view, opts, rows)
        log_detections(rec, overlay, result, clock, view, rows)
    as_run = _as_run_points(rec, run, opts, rows)
    log_points(rec, result, clock, as_run, opts, rows, views, error_color=overlay.color)
    log_series(rec, result, clock, as_run, rows)
    for view in views:
        log_images(rec, timeline, result, clock, view, opts, rows)
        log_overlay(rec, overlay, result, clock, view, rows)
    if opts.images is not ImageSelection.NONE:
        log_camera_videos(rec, run, clock, rows)
    log_camera_motion(rec, run, clock, rows)
    if run.attribution is not None and run.attribution.rig is not None:
        log_rig(rec, result, clock, run.attribution.rig, opts, rows)
    moving = run.timeline.transforms.stamp_ns[~run.timeline.transforms.is_static]
    log_text(rec, result, clock, [FindingView.of(f) for f in run.findings], rows,
             start_ns=int(moving.min()) if moving.size else None, verdict=_verdict(run),
             measured_instead=measured_instead(run.attribution))
    if run.attribution is not None:
        log_explained_error(rec, result, clock, run.attribution, rows)
        log_checks(rec, run.attribution, rows)
    return rows


def _as_run_points(
    rec: rr.RecordingStream, run: Run, opts: RerunOptions, rows: dict[str, int]
) -> dict[str, FloatArray]:
    """The robot's own points by entity leaf, as aligned; the chain's declared reference point where no
    reference was logged (and logged once itself)."""
    import rerun as rr

    as_run = {leaf: run.aligned.points(role) for role, leaf in ROLE_LEAF.items()}
    reference_point = run.chain.evidence.reference_point
    if reference_point is not None:
        declared = np.asarray(reference_point, dtype=float).reshape(3)
        have = np.all(np.isfinite(as_run["reference"]), axis=1)
        reference = np.where(have[:, None], as_run["reference"], declared)
        as_run["reference"] = np.where(run.replay.replayed[:, None], reference, np.nan)
        rec.log("/points/reference/declared",
                rr.Points3D([declared], colors=[REFERENCE_COLOR], radii=[opts.point_radius_m * 1.5],
                            labels=["declared reference"], show_labels=False),
                rr.CoordinateFrame(run.chain.frames.world), static=True)
        rows["/points/reference/declared"] = 1
    return as_run


def _verdict(run: Run) -> str:
    """What the findings panel says when there are no findings: the attribution's verdict, or that none ran."""
    if run.attribution is not None:
        return run.attribution.verdict
    why = f" ({run.not_attributed.detail})" if run.not_attributed else ""
    return f"No attribution{why}: the replay alone, nothing checked against evidence."


def _stderr(message: str) -> None:
    print(f"framechain: {message}", file=sys.stderr)


__all__ = [
    "EPISODE_TIME",
    "LOG_TIME",
    "OBS_INDEX",
    "SENSOR_TIME",
    "WALL_TIME",
    "Clock",
    "FindingView",
    "OutputMode",
    "RerunOptions",
    "RerunOutcome",
    "RerunSinkError",
    "RerunTarget",
    "default_blueprint",
    "display_available",
    "log_replay",
    "resolve_target",
    "stream_replay",
    "summary_markdown",
]
