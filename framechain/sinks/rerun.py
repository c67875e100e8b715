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
  (decimated); ``/camera/detections`` every observation's pixel as a 2D point.
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
  aligned them (:mod:`framechain.analysis.alignment`: matched to observations, in the hop's
  frame); ``/points/reference``: reference truth; ``/points/error/<hop>``: arrows from recomputed
  to as-run.
- ``/series/error_mm/<hop>`` (recomputed vs as-run, and ``target``/``reference``) and
  ``/series/gap_ms/<hop>`` (observation stamp minus the stamp of the transform sample used):
  ``Scalars``, one row per replayed observation.
- ``/log/findings``, ``/log/rejected``, ``/log/stale``: ``TextLog`` entries; ``/summary``: a
  Markdown ``TextDocument`` with the counts and the findings.

Timelines: ``sensor_time`` (header stamps), ``log_time`` (receive time in the log), and
``obs_index`` (row of the observation) on everything tied to an observation. Rerun's own
wall-clock ``log_time`` is switched off so the name means the log's receive time.

Everything per observation goes through ``send_columns`` (one call per entity, never one call per
observation per hop).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from framechain.analysis.alignment import AlignedEvidence, align_evidence
from framechain.analysis.attribute import Finding
from framechain.analysis.estimates import format_estimate, format_interval
from framechain.arrays import BoolArray, FloatArray, IntArray
from framechain.catalogue import HopName
from framechain.config.chain import ChainFrames
from framechain.replay import REPLAYED, ReplayResult, TransformBuffer
from framechain.replay.stamps import nearest
from framechain.sinks.overlay import (
    AS_RUN_COLOR,
    DETECTION_COLOR,
    RECOMPUTED_COLOR,
    ImageOverlay,
    ImageSelection,
    image_overlay,
    select_images,
)
from framechain.timeline import FramechainError, ImageFrameTable, PointRole, Timeline, normalize_frame
from framechain.timeline.frames import COMPRESSED_IMAGE_ENCODINGS, RAW_IMAGE_ENCODINGS, VIDEO_ENCODING

if TYPE_CHECKING:
    import rerun as rr
    import rerun.blueprint as rrb


#: Timeline of header (sensor) stamps.
SENSOR_TIME = "sensor_time"
#: Timeline of the log's receive times.
LOG_TIME = "log_time"
#: Timeline of the observation's row in the ObservationTable.
OBS_INDEX = "obs_index"

#: Suffix of the frames that carry the transforms the replay used (``base_link@replay``).
REPLAY_FRAME_SUFFIX = "@replay"
#: Suffix of the pinhole's child frame, as Rerun's own MCAP loader names it.
IMAGE_PLANE_SUFFIX = "_image_plane"

REFERENCE_COLOR = (44, 160, 44)
ERROR_COLOR = (214, 39, 40)
STALE_COLOR = (255, 187, 120)

#: The point at the output of each hop, by hop: (entity leaf, as-run role).
HOP_POINTS: tuple[tuple[HopName, str, PointRole], ...] = (
    (HopName.PIXEL_TO_CAMERA, "camera", PointRole.HOP_CAMERA),
    (HopName.CAMERA_TO_BODY, "body", PointRole.HOP_BODY),
    (HopName.BODY_TO_WORLD, "world", PointRole.HOP_WORLD),
)


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
class RerunOutcome:
    """What was written: the output actually used, notes for the user, and rows per entity."""

    mode: OutputMode
    path: Path | None
    url: str | None
    fell_back: bool
    notes: tuple[str, ...]
    rows: Mapping[str, int]


#: The entity leaf of each role's as-run points.
ROLE_LEAF: dict[PointRole, str] = {
    PointRole.HOP_CAMERA: "camera", PointRole.HOP_BODY: "body", PointRole.HOP_WORLD: "world",
    PointRole.TARGET: "target", PointRole.REFERENCE: "reference",
}


@dataclass(frozen=True)
class FindingView:
    """A finding as the sink (and ``framechain replay``) words it; the estimate text is
    :func:`~framechain.analysis.estimates.format_estimate`'s."""

    finding: Finding

    @classmethod
    def of(cls, finding: Finding) -> FindingView:
        return cls(finding)

    def text(self) -> str:
        """One line: fault, hop, estimate, share of the error, evidence and fix."""
        line = self.headline()
        f = self.finding
        if f.evidence:
            line += f" Evidence: {f.evidence.rstrip('.')}."
        if f.fix:
            line += f" Fix: {f.fix.rstrip('.')}."
        return line

    def headline(self) -> str:
        """Fault, hop, estimate and share of the error, without the evidence and fix sentences."""
        f = self.finding
        estimate = f"estimate {format_estimate(f.estimate)}"
        if f.interval:
            estimate += f" (95% interval {format_interval(f.interval)})"
        size = f"{f.error_m * 1e3:.1f} mm, {f.share * 100:.0f}% of the error, confidence {f.confidence:.2f}"
        return f"{f.fault.value} on {f.hop.value}; {estimate}; {size}."


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
    timeline: Timeline,
    result: ReplayResult,
    target: RerunTarget,
    *,
    findings: Sequence[Finding] = (),
    evidence: AlignedEvidence | None = None,
    reference_point: Sequence[float] | None = None,
    options: RerunOptions | None = None,
    env: Mapping[str, str] | None = None,
    notify: Callable[[str], None] | None = None,
) -> RerunOutcome:
    """Send one replay to ``target`` (save, connect or spawn), with the default blueprint.

    ``findings`` and ``evidence`` are an attribution's (``Attribution.findings``, ``.aligned``): the
    sink draws the evidence attribution used; without ``evidence`` it aligns the log's points itself
    (the same :func:`~framechain.analysis.alignment.align_evidence`). ``reference_point`` a declared
    world-frame target [x, y, z] in metres. ``notify`` receives notes for the user (default:
    stderr), such as the fallback from spawn to save. Ends with flush and disconnect (which writes
    the RRD footer).
    """
    import rerun as rr

    opts = options or RerunOptions()
    say = notify or _stderr
    chosen, note = resolve_target(target, env=env)
    notes: list[str] = []
    if note:
        notes.append(note)
        say(note)
    rec = rr.RecordingStream(opts.application_id, recording_id=opts.recording_id)
    shows_images = opts.images is not ImageSelection.NONE and len(timeline.image_frames) > 0
    if evidence is None:
        evidence = align_evidence(timeline.points, result.observations, result.frames,
                                  TransformBuffer.from_timeline(timeline))
    bounds = image_view_bounds(image_overlay(timeline, result, evidence, findings))
    blueprint = default_blueprint(result.frames, images=shows_images, image_bounds=bounds)
    fell_back = chosen.mode is not target.mode
    try:
        if chosen.mode is OutputMode.SAVE:
            assert chosen.path is not None
            chosen.path.parent.mkdir(parents=True, exist_ok=True)
            rec.save(chosen.path, default_blueprint=blueprint)
        elif chosen.mode is OutputMode.CONNECT:
            _check_listening(chosen.url)
            rec.connect_grpc(chosen.url, default_blueprint=blueprint)
        else:
            try:
                rec.spawn(default_blueprint=blueprint)
            except RuntimeError as err:  # no `rerun` executable on PATH
                path = chosen.path or Path("framechain.rrd")
                msg = f"cannot start the Rerun viewer ({err}); saving to {path} instead"
                notes.append(msg)
                say(msg)
                chosen = RerunTarget.save(path)
                fell_back = True
                rec.save(path, default_blueprint=blueprint)
        rows = log_replay(rec, timeline, result, findings=findings, evidence=evidence,
                          reference_point=reference_point, options=opts)
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


def image_view_bounds(overlay: ImageOverlay) -> tuple[float, float, float, float] | None:
    """(u_min, u_max, v_min, v_max) of the camera view: the image, widened to show most projected
    as-run points (the 90th percentile of how far they fall outside, at most one image size)."""
    have = overlay.width > 0
    if not have.any():
        return None
    w, h = float(overlay.width[have].max()), float(overlay.height[have].max())
    u0, u1, v0, v1 = -0.5, w - 0.5, -0.5, h - 0.5
    uv = overlay.as_run_uv[np.isfinite(overlay.as_run_uv).all(axis=1)]
    if uv.size:
        margin_u, margin_v = 0.04 * w, 0.04 * h
        u0 = max(min(u0, float(np.percentile(uv[:, 0], 10)) - margin_u), -w)
        u1 = min(max(u1, float(np.percentile(uv[:, 0], 90)) + margin_u), 2 * w)
        v0 = max(min(v0, float(np.percentile(uv[:, 1], 10)) - margin_v), -h)
        v1 = min(max(v1, float(np.percentile(uv[:, 1], 90)) + margin_v), 2 * h)
    return u0, u1, v0, v1


def default_blueprint(frames: ChainFrames, *, images: bool = False, collapse_panels: bool = False,
                      image_bounds: tuple[float, float, float, float] | None = None) -> rrb.Blueprint:
    """The 3D view in the world frame (and all observations' world points) beside the camera's 2D view
    (its images with the chain drawn on them when ``images``, else the depth frames); below them the
    per-hop error, the error in the image and the time gaps as series, and the findings.
    ``collapse_panels`` hides the viewer's side panels (screenshots); ``image_bounds`` (u_min, u_max,
    v_min, v_max) frames the camera view (see :func:`image_view_bounds`)."""
    import rerun.blueprint as rrb

    # With colour images, the depth cloud would bury the points: it stays in the depth tab.
    world = rrb.Spatial3DView(
        name=f"World ({frames.world})", origin="/",
        contents=["+ /**", "- /series/**", "- /log/**", "- /summary", "- /camera/overlay/**",
                  *(["- /camera/depth"] if images else [])],
        spatial_information=rrb.SpatialInformation(target_frame=frames.world),
    )
    history = rrb.Spatial3DView(
        name="All observations (world points)", origin="/",
        contents=["+ /points/recomputed/world", "+ /points/as_run/world", "+ /points/as_run/target",
                  "+ /points/reference/**", "+ /points/error/world", "+ /frames/**", "+ /tf/**"],
        spatial_information=rrb.SpatialInformation(target_frame=frames.world),
        time_ranges=[rrb.VisibleTimeRange(name, start=rrb.TimeRangeBoundary.infinite(),
                                          end=rrb.TimeRangeBoundary.infinite())
                     for name in (SENSOR_TIME, LOG_TIME, OBS_INDEX)],
    )
    plane = rrb.SpatialInformation(target_frame=frames.camera + IMAGE_PLANE_SUFFIX)
    bounds = None if image_bounds is None else rrb.VisualBounds2D(x_range=image_bounds[:2], y_range=image_bounds[2:])
    camera = rrb.Spatial2DView(
        name=f"Camera ({frames.camera})", origin="/camera",
        contents=["+ /camera/**", "- /camera/depth"] if images else ["+ /camera/**"],
        spatial_information=plane, visual_bounds=bounds,
    )
    cameras: rrb.Tabs | rrb.Spatial2DView = camera
    if images:
        depth = rrb.Spatial2DView(name=f"Depth ({frames.camera})", origin="/camera",
                                  contents=["+ /camera/depth", "+ /camera/detections"], spatial_information=plane)
        cameras = rrb.Tabs(camera, depth)
    errors = rrb.TimeSeriesView(name="Per-hop error (mm)", origin="/series/error_mm")
    pixels = rrb.TimeSeriesView(name="As-run vs recomputed in the image (px)", origin="/series/error_px")
    gaps = rrb.TimeSeriesView(name="Per-hop time gap (ms)", origin="/series/gap_ms")
    text = rrb.Tabs(rrb.TextLogView(name="Findings and rejections", origin="/log"),
                    rrb.TextDocumentView(name="Summary", origin="/summary"))
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(rrb.Tabs(world, history), cameras, column_shares=[1, 1]),
            rrb.Horizontal(errors, rrb.Tabs(pixels, gaps) if images else gaps, text, column_shares=[2, 2, 2]),
            row_shares=[3, 2],
        ),
        rrb.TimePanel(state="collapsed" if collapse_panels else "expanded", timeline=SENSOR_TIME),
        collapse_panels=collapse_panels,
    )


def log_replay(
    rec: rr.RecordingStream,
    timeline: Timeline,
    result: ReplayResult,
    *,
    findings: Sequence[Finding] = (),
    evidence: AlignedEvidence | None = None,
    reference_point: Sequence[float] | None = None,
    options: RerunOptions | None = None,
) -> dict[str, int]:
    """Log everything of one replay to an open recording; returns rows logged per entity path.

    The caller owns ``rec`` (its sink, flush and disconnect), so this also serves notebooks
    (``rec.notebook_show()``) and in-memory recordings.
    """
    import rerun as rr

    opts = options or RerunOptions()
    rr.set_log_time_enabled(False, recording=rec)
    rr.set_log_tick_enabled(False, recording=rec)
    if opts.recording_name:
        rec.send_recording_name(opts.recording_name)
    rows: dict[str, int] = {}
    frames = result.frames
    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    _log_frame_tree(rec, timeline, frames, opts, rows)
    _log_used_transforms(rec, result, rows)
    _log_camera(rec, timeline, result, opts, rows)
    if evidence is None:
        evidence = align_evidence(timeline.points, result.observations, frames, TransformBuffer.from_timeline(timeline))
    if len(evidence) != len(result.observations) or not np.array_equal(evidence.obs_id, result.observations.obs_id):
        raise RerunSinkError("the aligned evidence is not that of this replay's observations")
    as_run = {leaf: evidence.points(role) for role, leaf in ROLE_LEAF.items()}
    if reference_point is not None:
        declared = np.asarray(reference_point, dtype=float).reshape(3)
        have = _finite_rows(as_run["reference"])
        reference = np.where(have[:, None], as_run["reference"], declared)
        as_run["reference"] = np.where(result.replayed[:, None], reference, np.nan)
        rec.log("/points/reference/declared",
                rr.Points3D([declared], colors=[REFERENCE_COLOR], radii=[opts.point_radius_m * 1.5],
                            labels=["declared reference"]),
                rr.CoordinateFrame(frames.world), static=True)
        rows["/points/reference/declared"] = 1
    _log_points(rec, result, as_run, opts, rows)
    _log_series(rec, result, as_run, rows)
    _log_images(rec, timeline, result, opts, rows)
    _log_overlay(rec, image_overlay(timeline, result, evidence, findings), result, rows)
    _log_text(rec, result, [FindingView.of(f) for f in findings], rows)
    return rows


# ----------------------------------------------------------------------------------------------
# Logging helpers


def _finite_rows(xyz: FloatArray) -> BoolArray:
    out: BoolArray = np.all(np.isfinite(xyz), axis=1)
    return out


def _stderr(message: str) -> None:
    print(f"framechain: {message}", file=sys.stderr)


def _entity_part(name: str) -> str:
    import rerun as rr

    escaped: str = rr.escape_entity_path_part(name)
    return escaped


def _stamp_column(name: str, ns: npt.ArrayLike) -> rr.TimeColumn:
    import rerun as rr

    return rr.TimeColumn(name, timestamp=np.asarray(ns, dtype=np.int64).astype("datetime64[ns]"))


def _obs_indexes(result: ReplayResult, rows: IntArray) -> list[rr.TimeColumn]:
    import rerun as rr

    obs = result.observations
    return [
        _stamp_column(SENSOR_TIME, obs.stamp_ns[rows]),
        _stamp_column(LOG_TIME, obs.log_time_ns[rows]),
        rr.TimeColumn(OBS_INDEX, sequence=rows.astype(np.int64)),
    ]


def _log_frame_tree(
    rec: rr.RecordingStream, timeline: Timeline, frames: ChainFrames, opts: RerunOptions, rows: dict[str, int]
) -> None:
    """``/tf/<child>`` per child frame: static edges once as static, dynamic edges in bulk."""
    import rerun as rr

    tf = timeline.transforms
    names: set[str] = {frames.world, frames.body, frames.camera}
    for child in np.unique(tf.child):
        sel = np.flatnonzero(tf.child == child)
        entity = f"/tf/{_entity_part(str(child))}"
        names.add(str(child))
        names.update(str(p) for p in np.unique(tf.parent[sel]))
        dynamic = sel[~tf.is_static[sel]]
        if dynamic.size == 0:
            # Static data has no time and overrides temporal data: the latest static sample only.
            last = sel[np.argmax(tf.stamp_ns[sel])]
            rec.log(entity, rr.Transform3D(
                translation=tf.translation[last], quaternion=tf.quat_xyzw[last],
                parent_frame=str(tf.parent[last]), child_frame=str(child),
            ), static=True)
            rows[entity] = 1
            continue
        # A child with dynamic samples stays temporal (static samples of it, if any, at their stamps).
        use = sel[np.argsort(tf.stamp_ns[sel], kind="stable")]
        rec.send_columns(
            entity,
            indexes=[_stamp_column(SENSOR_TIME, tf.stamp_ns[use]), _stamp_column(LOG_TIME, tf.log_time_ns[use])],
            columns=rr.Transform3D.columns(
                translation=tf.translation[use], quaternion=tf.quat_xyzw[use],
                parent_frame=tf.parent[use].tolist(), child_frame=tf.child[use].tolist(),
            ),
        )
        rows[entity] = int(use.size)
    names.update({frames.body + REPLAY_FRAME_SUFFIX, frames.camera + REPLAY_FRAME_SUFFIX})
    for name in sorted(names):
        if name.endswith(REPLAY_FRAME_SUFFIX):
            entity = f"/frames/replay/{_entity_part(name.removesuffix(REPLAY_FRAME_SUFFIX))}"
        else:
            entity = f"/frames/{_entity_part(name)}"
        rec.log(entity, rr.CoordinateFrame(name), rr.TransformAxes3D(opts.axis_length_m, show_frame=True),
                static=True)
        rows[entity] = 1


def _log_used_transforms(rec: rr.RecordingStream, result: ReplayResult, rows: dict[str, int]) -> None:
    """The transforms the replay used, per replayed observation, at the observation's time."""
    import rerun as rr

    frames = result.frames
    body_replay = frames.body + REPLAY_FRAME_SUFFIX
    cam_replay = frames.camera + REPLAY_FRAME_SUFFIX
    ok = np.flatnonzero(result.replayed)
    if ok.size == 0:
        return
    for entity, lookup, parent, child in (
        ("/replay/world_from_body", result.world_from_body, frames.world, body_replay),
        ("/replay/body_from_cam", result.body_from_cam, body_replay, cam_replay),
    ):
        rec.send_columns(
            entity, indexes=_obs_indexes(result, ok),
            columns=rr.Transform3D.columns(
                translation=lookup.translation[ok], quaternion=lookup.quat_xyzw[ok],
                parent_frame=[parent] * ok.size, child_frame=[child] * ok.size,
            ),
        )
        rows[entity] = int(ok.size)


def _log_camera(
    rec: rr.RecordingStream, timeline: Timeline, result: ReplayResult, opts: RerunOptions, rows: dict[str, int]
) -> None:
    """Pinhole (static, or over time if the intrinsics change), depth frames, detections."""
    import rerun as rr

    frames = result.frames
    plane = frames.camera + IMAGE_PLANE_SUFFIX
    cams = timeline.cameras
    mine = np.flatnonzero(cams.frame == normalize_frame(frames.camera))
    if mine.size:
        mine = mine[np.argsort(cams.stamp_ns[mine], kind="stable")]
        k = cams.K[mine]
        res = np.stack([cams.width[mine], cams.height[mine]], axis=1).astype(float)
        changes = np.concatenate([[True], (np.abs(np.diff(k, axis=0)).max(axis=(1, 2)) > 0)
                                  | (np.diff(res, axis=0) != 0).any(axis=1)])
        keep = mine[changes]
        if keep.size == 1:
            rec.log("/camera", rr.Pinhole(
                image_from_camera=cams.K[keep[0]], resolution=res[changes][0],
                camera_xyz=rr.ViewCoordinates.RDF, parent_frame=frames.camera, child_frame=plane,
                image_plane_distance=0.5,
            ), static=True)
        else:
            rec.send_columns(
                "/camera",
                indexes=[_stamp_column(SENSOR_TIME, cams.stamp_ns[keep]),
                         _stamp_column(LOG_TIME, cams.log_time_ns[keep])],
                columns=rr.Pinhole.columns(
                    image_from_camera=cams.K[keep], resolution=res[changes],
                    camera_xyz=[rr.ViewCoordinates.RDF] * keep.size,
                    parent_frame=[frames.camera] * keep.size, child_frame=[plane] * keep.size,
                ),
            )
        rows["/camera"] = int(keep.size)
    _log_depth(rec, timeline, result, opts, plane, rows)
    obs = result.observations
    if len(obs):
        every = np.arange(len(obs), dtype=np.int64)
        colors = np.where(result.replayed[:, None], np.array(RECOMPUTED_COLOR), np.array(ERROR_COLOR))
        colors[result.stale] = STALE_COLOR
        labels = [f"obs {i} {lab}".rstrip() + ("" if s == REPLAYED else f" ({s})")
                  for i, lab, s in zip(obs.obs_id.tolist(), obs.label.tolist(), result.status.tolist(), strict=True)]
        rec.log("/camera/detections", rr.CoordinateFrame(plane), static=True)
        _send_per_stamp(rec, "/camera/detections", result, every, lambda sel: rr.Points2D.columns(
            positions=np.stack([obs.u[sel], obs.v[sel]], axis=1), colors=colors[sel].astype(np.uint8),
            labels=[labels[i] for i in sel.tolist()], radii=np.full(sel.size, 6.0)))
        rows["/camera/detections"] = len(obs)


def _log_images(
    rec: rr.RecordingStream, timeline: Timeline, result: ReplayResult, opts: RerunOptions, rows: dict[str, int]
) -> None:
    """The camera's images under its image plane: raw as ``Image``, JPEG/PNG as ``EncodedImage`` (bytes
    as logged), frames of a video file as ``VideoFrameReference`` into one ``AssetVideo`` per file."""
    import rerun as rr

    images = timeline.image_frames
    chosen = select_images(timeline, result, opts.images)
    if chosen.size == 0:
        return
    plane = result.frames.camera + IMAGE_PLANE_SUFFIX
    enc = images.encoding[chosen]
    raw = chosen[np.isin(enc, list(RAW_IMAGE_ENCODINGS))]
    compressed = chosen[np.isin(enc, list(COMPRESSED_IMAGE_ENCODINGS))]
    if raw.size or compressed.size:
        rec.log("/camera/image", rr.CoordinateFrame(plane), static=True)
    if raw.size:
        rec.send_columns(
            "/camera/image", indexes=_image_indexes(images, result, raw),
            columns=rr.Image.columns(buffer=[images.load(int(i)) for i in raw],
                                     format=[_image_format(str(images.encoding[i]), int(images.width[i]),
                                                           int(images.height[i])) for i in raw]),
        )
    if compressed.size:
        rec.send_columns(
            "/camera/image", indexes=_image_indexes(images, result, compressed),
            columns=rr.EncodedImage.columns(blob=[images.load(int(i)) for i in compressed],
                                            media_type=[f"image/{images.encoding[i]}" for i in compressed]),
        )
    if raw.size or compressed.size:
        rows["/camera/image"] = int(raw.size + compressed.size)
    video = chosen[enc == VIDEO_ENCODING]
    for k, path in enumerate(np.unique(images.video_path[video]).tolist()):
        entity = "/camera/video" if k == 0 else f"/camera/video/{k}"
        frames = video[images.video_path[video] == path]
        rec.log(entity, rr.AssetVideo(path=path), rr.CoordinateFrame(plane), static=True)
        rec.send_columns(entity, indexes=_image_indexes(images, result, frames),
                         columns=rr.VideoFrameReference.columns_nanos(images.video_time_ns[frames]))
        rows[entity] = int(frames.size)


def _image_format(encoding: str, width: int, height: int) -> rr.components.ImageFormat:
    import rerun as rr

    channels, dtype = RAW_IMAGE_ENCODINGS[encoding]
    bgr = encoding.startswith("bgr")
    models: dict[int, Literal["L", "RGB", "BGR", "RGBA", "BGRA"]] = {
        1: "L", 3: "BGR" if bgr else "RGB", 4: "BGRA" if bgr else "RGBA"}
    datatypes: dict[str, Literal["U8", "U16", "F32"]] = {"u1": "U8", "<u2": "U16", "<f4": "F32"}
    return rr.components.ImageFormat(width=width, height=height, color_model=models[channels],
                                     channel_datatype=datatypes[dtype])


def _image_indexes(images: ImageFrameTable, result: ReplayResult, rows: IntArray) -> list[rr.TimeColumn]:
    """Sensor and log time of each image, and the row of the observation nearest it (so images
    follow the ``obs_index`` timeline too)."""
    import rerun as rr

    obs = result.observations
    order = np.argsort(obs.stamp_ns, kind="stable")
    if obs.stamp_ns.size:
        near = order[nearest(obs.stamp_ns[order], images.stamp_ns[rows])]
    else:
        near = np.zeros(rows.size, dtype=np.int64)
    return [_stamp_column(SENSOR_TIME, images.stamp_ns[rows]), _stamp_column(LOG_TIME, images.log_time_ns[rows]),
            rr.TimeColumn(OBS_INDEX, sequence=near.astype(np.int64))]


def _send_per_stamp(rec: rr.RecordingStream, entity: str, result: ReplayResult, sel: IntArray,
                    columns: Callable[[IntArray], rr.ComponentColumnList]) -> None:
    """One row per observation stamp holding every observation of that stamp (several tags in one
    image): a later row at the same time would hide the earlier ones in the viewer."""
    obs = result.observations
    sel = sel[np.argsort(obs.stamp_ns[sel], kind="stable")]
    starts = np.flatnonzero(np.concatenate([[True], np.diff(obs.stamp_ns[sel]) != 0]))
    lengths = np.diff(np.append(starts, sel.size))
    rec.send_columns(entity, indexes=_obs_indexes(result, sel[starts]), columns=columns(sel).partition(lengths=lengths))


def _log_overlay(rec: rr.RecordingStream, overlay: ImageOverlay, result: ReplayResult, rows: dict[str, int]) -> None:
    """The chain on the image: corners, projected recomputed and as-run points, the line between them.

    Observations with one stamp (several tags in one image) share one row per entity, so the viewer
    shows all of them at that time (a later row at the same time would hide the earlier ones).
    """
    import rerun as rr

    obs = result.observations
    if len(obs) == 0:
        return
    plane = result.frames.camera + IMAGE_PLANE_SUFFIX

    def send(entity: str, sel: IntArray, columns: Callable[[IntArray], rr.ComponentColumnList]) -> None:
        if sel.size == 0:
            return
        rec.log(entity, rr.CoordinateFrame(plane), static=True)
        _send_per_stamp(rec, entity, result, sel, columns)
        rows[entity] = int(sel.size)

    radius = np.float32(max(2.0, float(np.nanmax(overlay.width, initial=320)) / 160.0))
    corners = np.flatnonzero(np.isfinite(overlay.corners_px).all(axis=(1, 2)))
    send("/camera/overlay/corners", corners, lambda sel: rr.LineStrips2D.columns(
        strips=[np.vstack([q, q[:1]]) for q in overlay.corners_px[sel]],
        colors=np.tile(np.array(DETECTION_COLOR, dtype=np.uint8), (sel.size, 1)),
        radii=np.full(sel.size, radius / 2, dtype=np.float32)))
    def points(uv: FloatArray, color: tuple[int, int, int], what: str) -> Callable[[IntArray], rr.ComponentColumnList]:
        def columns(sel: IntArray) -> rr.ComponentColumnList:
            return rr.Points2D.columns(
                positions=uv[sel], colors=np.tile(np.array(color, dtype=np.uint8), (sel.size, 1)),
                radii=np.full(sel.size, radius * 1.5, dtype=np.float32), labels=[what] * sel.size,
                show_labels=[False] * sel.size)

        return columns

    for name, uv, color in (("recomputed", overlay.recomputed_uv, RECOMPUTED_COLOR),
                            ("as_run", overlay.as_run_uv, AS_RUN_COLOR)):
        have = np.flatnonzero(np.isfinite(uv).all(axis=1))
        what = "recomputed world point" if name == "recomputed" else f"as-run {overlay.as_run_role} point"
        send(f"/camera/overlay/{name}", have, points(uv, color, what))
    both = np.flatnonzero(np.isfinite(overlay.recomputed_uv).all(axis=1) & np.isfinite(overlay.as_run_uv).all(axis=1))
    error_px = overlay.error_px
    send("/camera/overlay/error", both, lambda sel: rr.LineStrips2D.columns(
        strips=[np.stack([overlay.recomputed_uv[i], overlay.as_run_uv[i]]) for i in sel.tolist()],
        colors=np.tile(np.array(overlay.color, dtype=np.uint8), (sel.size, 1)),
        radii=np.full(sel.size, radius / 2, dtype=np.float32),
        labels=[f"{error_px[i]:.0f} px: {overlay.label()}" for i in sel.tolist()]))
    if both.size:
        entity = "/series/error_px/as_run"
        rec.log(entity, rr.SeriesLines(names=["as-run vs recomputed in the image (px)"], colors=[overlay.color]),
                static=True)
        rec.send_columns(entity, indexes=_obs_indexes(result, both),
                         columns=rr.Scalars.columns(scalars=error_px[both]))
        rows[entity] = int(both.size)


def _log_depth(
    rec: rr.RecordingStream, timeline: Timeline, result: ReplayResult, opts: RerunOptions, plane: str,
    rows: dict[str, int],
) -> None:
    """Depth frames of the chain camera near observations, decimated to ``max_images``.

    Logged as uint16 millimetres (``meter=1000``): a VGA frame is 0.6 MB, so the default cap of 30
    keeps a recording under about 20 MB; lazily decoded frames cost about 70 ms each from an MCAP.
    """
    import rerun as rr

    depth = timeline.depth_frames
    mine = np.flatnonzero(depth.frame == normalize_frame(result.frames.camera))
    obs = result.observations
    if mine.size == 0 or len(obs) == 0 or opts.max_images <= 0 or depth.loader is None:
        return
    mine = mine[np.argsort(depth.stamp_ns[mine], kind="stable")]
    stamps = depth.stamp_ns[mine]
    # The frame each observation used (or the nearest within the window when depth came with it).
    want = np.where(result.depth_stamp_ns > 0, result.depth_stamp_ns, obs.stamp_ns)
    pick = nearest(stamps, want)
    near = np.abs(stamps[pick] - want) <= opts.image_window_ns
    chosen = np.unique(mine[pick[near]])
    if chosen.size > opts.max_images:
        chosen = chosen[np.linspace(0, chosen.size - 1, opts.max_images).round().astype(np.int64)]
        chosen = np.unique(chosen)
    images = [_depth_mm(depth.load(int(i))) for i in chosen]
    formats = [rr.components.ImageFormat(width=im.shape[1], height=im.shape[0], channel_datatype="U16")
               for im in images]
    rec.log("/camera/depth", rr.CoordinateFrame(plane), static=True)
    rec.send_columns(
        "/camera/depth",
        indexes=[_stamp_column(SENSOR_TIME, depth.stamp_ns[chosen]),
                 _stamp_column(LOG_TIME, depth.log_time_ns[chosen])],
        columns=rr.DepthImage.columns(buffer=[im.tobytes() for im in images], format=formats,
                                      meter=np.full(chosen.size, 1000.0, dtype=np.float32)),
    )
    rows["/camera/depth"] = int(chosen.size)


def _depth_mm(image_m: npt.NDArray[np.float32]) -> npt.NDArray[np.uint16]:
    """Depth in metres as uint16 millimetres (half the bytes of float32); 0 where there is none."""
    mm = np.asarray(image_m, dtype=np.float64) * 1000.0
    valid = np.isfinite(mm) & (mm > 0) & (mm < 65535.5)
    return np.ascontiguousarray(np.where(valid, np.rint(mm), 0).astype(np.uint16))


def _log_points(
    rec: rr.RecordingStream, result: ReplayResult, as_run: Mapping[str, FloatArray], opts: RerunOptions,
    rows: dict[str, int],
) -> None:
    """Recomputed and as-run points at every hop, the reference, arrows recomputed -> as-run."""
    import rerun as rr

    frames = result.frames
    hop_frame = {"camera": frames.camera + REPLAY_FRAME_SUFFIX, "body": frames.body + REPLAY_FRAME_SUFFIX,
                 "world": frames.world, "target": frames.world}
    recomputed = {"camera": result.p_cam, "body": result.p_body, "world": result.p_world,
                  "target": result.p_world}
    obs_id = result.observations.obs_id
    radius = opts.point_radius_m

    def send_points(entity: str, frame: str, xyz: FloatArray, color: tuple[int, int, int], what: str) -> None:
        sel = np.flatnonzero(np.isfinite(xyz).all(axis=1))
        if sel.size == 0:
            return
        rec.log(entity, rr.CoordinateFrame(frame), static=True)
        rec.send_columns(
            entity, indexes=_obs_indexes(result, sel),
            columns=rr.Points3D.columns(
                positions=xyz[sel], colors=np.tile(np.array(color, dtype=np.uint8), (sel.size, 1)),
                radii=np.full(sel.size, radius, dtype=np.float32),
                labels=[f"obs {i} {what}" for i in obs_id[sel].tolist()],
                show_labels=[False] * sel.size,  # on hover: several overlap at one point
            ),
        )
        rows[entity] = int(sel.size)

    for leaf in ("camera", "body", "world"):
        send_points(f"/points/recomputed/{leaf}", hop_frame[leaf], recomputed[leaf], RECOMPUTED_COLOR,
                    f"recomputed ({leaf})")
    for leaf in ("camera", "body", "world", "target"):
        logged = as_run[leaf]
        send_points(f"/points/as_run/{leaf}", hop_frame[leaf], logged, AS_RUN_COLOR, f"as-run ({leaf})")
        both = np.flatnonzero(np.isfinite(logged).all(axis=1) & np.isfinite(recomputed[leaf]).all(axis=1))
        if both.size == 0:
            continue
        entity = f"/points/error/{leaf}"
        rec.log(entity, rr.CoordinateFrame(hop_frame[leaf]), static=True)
        delta = logged[both] - recomputed[leaf][both]
        rec.send_columns(
            entity, indexes=_obs_indexes(result, both),
            columns=rr.Arrows3D.columns(
                origins=recomputed[leaf][both], vectors=delta,
                colors=np.tile(np.array(ERROR_COLOR, dtype=np.uint8), (both.size, 1)),
                radii=np.full(both.size, radius / 4, dtype=np.float32),
                labels=[f"{np.linalg.norm(d) * 1e3:.1f} mm" for d in delta],
            ),
        )
        rows[entity] = int(both.size)
    send_points("/points/reference/matched", frames.world, as_run["reference"], REFERENCE_COLOR, "reference")


def _log_series(
    rec: rr.RecordingStream, result: ReplayResult, as_run: Mapping[str, FloatArray], rows: dict[str, int]
) -> None:
    """Per-hop error (mm) where as-run exists and per-hop time gap (ms), one row per observation."""
    import rerun as rr

    ok = result.replayed
    recomputed = {"camera": result.p_cam, "body": result.p_body, "world": result.p_world}

    def send(entity: str, sel: IntArray, values: FloatArray, name: str, color: tuple[int, int, int]) -> None:
        if sel.size == 0:
            return
        rec.log(entity, rr.SeriesLines(names=[name], colors=[color]), rr.SeriesPoints(
            names=[name], colors=[color], marker_sizes=[2.0]), static=True)
        rec.send_columns(entity, indexes=_obs_indexes(result, sel), columns=rr.Scalars.columns(scalars=values))
        rows[entity] = int(sel.size)

    palette = {HopName.PIXEL_TO_CAMERA: (148, 103, 189), HopName.CAMERA_TO_BODY: (31, 119, 180),
               HopName.BODY_TO_WORLD: (214, 39, 40)}
    for hop, leaf, _role in HOP_POINTS:
        err = np.linalg.norm(as_run[leaf] - recomputed[leaf], axis=1)
        sel = np.flatnonzero(ok & np.isfinite(err))
        send(f"/series/error_mm/{hop.value}", sel, err[sel] * 1e3, f"{hop.value} error (mm)", palette[hop])
    for leaf, color in (("target", AS_RUN_COLOR), ("reference", REFERENCE_COLOR)):
        err = np.linalg.norm(as_run[leaf] - result.p_world, axis=1)
        sel = np.flatnonzero(ok & np.isfinite(err))
        send(f"/series/error_mm/{leaf}", sel, err[sel] * 1e3, f"world vs {leaf} (mm)", color)

    hops = result.hops
    index_of = _index_of(result.observations.obs_id)
    for hop in HopName:
        sel_rows = np.flatnonzero((hops.hop == hop.value) & (hops.status == REPLAYED))
        obs_rows = index_of(hops.obs_id[sel_rows])
        order = np.argsort(obs_rows, kind="stable")
        send(f"/series/gap_ms/{hop.value}", obs_rows[order], hops.gap_ns[sel_rows][order] / 1e6,
             f"{hop.value} gap (ms)", palette[hop])


def _index_of(obs_ids: IntArray) -> Callable[[IntArray], IntArray]:
    order = np.argsort(obs_ids, kind="stable")

    def lookup(ids: IntArray) -> IntArray:
        found: IntArray = order[np.searchsorted(obs_ids[order], ids)]
        return found

    return lookup


def _log_text(rec: rr.RecordingStream, result: ReplayResult, findings: Iterable[FindingView],
              rows: dict[str, int]) -> None:
    """Findings (at the first observation), rejected and stale observations, and a summary."""
    import rerun as rr

    obs = result.observations
    budget_ms = result.latency_budget_ns / 1e6
    found = list(findings)
    if found and len(obs):
        first = np.full(len(found), int(np.argmin(obs.stamp_ns)), dtype=np.int64)
        rec.send_columns("/log/findings", indexes=_obs_indexes(result, first),
                         columns=rr.TextLog.columns(text=[f.text() for f in found],
                                                    level=[rr.TextLogLevel.ERROR] * len(found)))
        rows["/log/findings"] = len(found)
    elif found:
        rec.log("/log/findings", rr.TextLog("\n".join(f.text() for f in found), level=rr.TextLogLevel.ERROR),
                static=True)
        rows["/log/findings"] = 1
    rejected = np.flatnonzero(~result.replayed)
    if rejected.size:
        texts = [_rejection_text(result, int(i)) for i in rejected]
        rec.send_columns("/log/rejected", indexes=_obs_indexes(result, rejected),
                         columns=rr.TextLog.columns(text=texts, level=[rr.TextLogLevel.WARN] * rejected.size))
        rows["/log/rejected"] = int(rejected.size)
    stale = np.flatnonzero(result.stale & result.replayed)
    if stale.size:
        hops = result.hops
        index_of = _index_of(obs.obs_id)
        gaps = np.zeros((len(obs), len(HopName)), dtype=np.int64)
        for j, hop in enumerate(HopName):
            sel = np.flatnonzero(hops.hop == hop.value)
            gaps[index_of(hops.obs_id[sel]), j] = hops.gap_ns[sel]
        texts = []
        for i in stale.tolist():
            worst = int(np.argmax(np.abs(gaps[i])))
            texts.append(f"obs {int(obs.obs_id[i])} stale: {list(HopName)[worst].value} used a sample "
                         f"{gaps[i, worst] / 1e6:+.1f} ms from the observation stamp (budget {budget_ms:g} ms)")
        rec.send_columns("/log/stale", indexes=_obs_indexes(result, stale),
                         columns=rr.TextLog.columns(text=texts, level=[rr.TextLogLevel.INFO] * stale.size))
        rows["/log/stale"] = int(stale.size)
    rec.log("/summary", rr.TextDocument(summary_markdown(result, found), media_type=rr.MediaType.MARKDOWN),
            static=True)
    rows["/summary"] = 1


def _rejection_text(result: ReplayResult, i: int) -> str:
    obs = result.observations
    reason = str(result.status[i])
    frames = result.frames
    detail = ""
    if reason in ("extrapolation", "missing_edge"):
        for name, lookup in (("camera_to_body", result.body_from_cam), ("body_to_world", result.world_from_body)):
            if not bool(lookup.ok[i]):
                detail = f" on {name} ({lookup.target} <- {lookup.source})"
                break
    elif reason in ("no_depth", "depth_invalid"):
        detail = f" (depth {result.depth_m[i]:.3g} m)" if np.isfinite(result.depth_m[i]) else ""
    elif reason == "outside_image":
        detail = f" (pixel {obs.u[i]:.1f}, {obs.v[i]:.1f})"
    elif reason == "no_camera_info":
        detail = f" (no CameraInfo for {frames.camera})"
    return f"obs {int(obs.obs_id[i])} {obs.label[i]} rejected: {reason}{detail}".replace("  ", " ")


def summary_markdown(result: ReplayResult, findings: Sequence[FindingView] = ()) -> str:
    """Counts (total, replayed, rejected per reason, stale) and findings as Markdown."""
    counts = result.counts()
    rejected = counts["rejected"]
    assert isinstance(rejected, dict)
    frames = result.frames
    lines = [
        "# framechain replay",
        "",
        f"Chain: `{frames.camera}` -> `{frames.body}` -> `{frames.world}`; "
        f"latency budget {result.latency_budget_ns / 1e6:g} ms.",
        "",
        "| observations | count |",
        "| --- | ---: |",
        f"| total | {counts['total']} |",
        f"| replayed | {counts['replayed']} |",
        *[f"| rejected: {reason} | {n} |" for reason, n in sorted(rejected.items())],
        f"| stale (replayed) | {counts['stale']} |",
    ]
    if findings:
        lines += ["", "## Findings", "", *[f"- {f.text()}" for f in findings]]
    return "\n".join(lines) + "\n"


__all__ = [
    "LOG_TIME",
    "OBS_INDEX",
    "SENSOR_TIME",
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

