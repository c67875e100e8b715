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
- ``/points/recomputed/{camera,body,world}``: the replay's point at every hop, in the hop's frame;
  ``/points/as_run/{camera,body,world,target}``: the robot's own logged points, matched to
  observations; ``/points/reference``: reference truth; ``/points/error/<hop>``: arrows from
  recomputed to as-run.
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

import dataclasses
import os
import sys
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from framechain.analysis.attribute import POINT_MATCH_NS, REFERENCE_MATCH_NS
from framechain.replay import REPLAYED, HopName, ReplayResult, TransformBuffer, transform_points
from framechain.replay.stamps import nearest
from framechain.timeline import (
    ChainFrames,
    FramechainError,
    PointRole,
    PointTable,
    Timeline,
    normalize_frame,
)
from framechain.timeline.arrays import BoolArray, FloatArray, IntArray

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

RECOMPUTED_COLOR = (31, 119, 180)
AS_RUN_COLOR = (255, 127, 14)
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
    #: As-run points without an ``obs_id`` match the observation with the nearest stamp within this.
    match_tolerance_ns: int = POINT_MATCH_NS
    #: Reference points (motion capture) match the nearest observation within this.
    reference_tolerance_ns: int = REFERENCE_MATCH_NS
    point_radius_m: float = 0.02
    axis_length_m: float = 0.2


@dataclass(frozen=True)
class RerunOutcome:
    """What was written: the output actually used, notes for the user, and rows per entity."""

    mode: OutputMode
    path: Path | None
    url: str | None
    fell_back: bool
    notes: tuple[str, ...]
    rows: Mapping[str, int]


@dataclass(frozen=True)
class AsRunPoints:
    """The robot's own logged points, one row per observation in the chain frame of their hop.

    Each array is (N, 3), NaN where the robot logged nothing for that observation (or the point's
    frame could not be brought into the hop's frame).
    """

    camera: FloatArray
    body: FloatArray
    world: FloatArray
    target: FloatArray
    reference: FloatArray

    def by_leaf(self, leaf: str) -> FloatArray:
        value: FloatArray = getattr(self, leaf)
        return value


@dataclass(frozen=True)
class FindingView:
    """A finding as the sink renders it (from the attribution engine's objects or plain dicts)."""

    fault: str
    hop: str
    estimate: Any = None
    interval: Any = None  # {key: [low, high]} for estimate keys
    share: float | None = None
    error_m: float | None = None
    confidence: float | None = None
    evidence: str = ""
    fix: str = ""

    @classmethod
    def of(cls, finding: Mapping[str, Any] | object) -> FindingView:
        """Read the known fields from a mapping, a dataclass or any object with attributes."""
        if isinstance(finding, FindingView):
            return finding
        if isinstance(finding, Mapping):
            get: Callable[[str], Any] = finding.get
        elif dataclasses.is_dataclass(finding) and not isinstance(finding, type):
            raw = dataclasses.asdict(finding)
            get = raw.get
        else:

            def get(name: str) -> Any:
                return getattr(finding, name, None)

        def number(name: str) -> float | None:
            value = get(name)
            return None if value is None else float(value)

        return cls(
            fault=_enum_text(get("fault") or "unknown"), hop=_enum_text(get("hop") or ""),
            estimate=get("estimate"), interval=get("interval"),
            share=number("share"), error_m=number("error_m"), confidence=number("confidence"),
            evidence=str(get("evidence") or ""), fix=str(get("fix") or ""),
        )

    def text(self) -> str:
        """One line: fault, hop, estimate, share of the error, evidence and fix."""
        line = self.headline()
        if self.evidence:
            line += f" Evidence: {self.evidence.rstrip('.')}."
        if self.fix:
            line += f" Fix: {self.fix.rstrip('.')}."
        return line

    def headline(self) -> str:
        """Fault, hop, estimate and share of the error, without the evidence and fix sentences."""
        head = f"{_enum_text(self.fault)}"
        if self.hop:
            head += f" on {_enum_text(self.hop)}"
        parts = [head]
        if self.estimate is not None:
            estimate = f"estimate {_format_estimate(self.estimate)}"
            if isinstance(self.interval, Mapping) and self.interval:
                estimate += f" (95% interval {_format_estimate(self.interval)})"
            parts.append(estimate)
        size = []
        if self.error_m is not None:
            size.append(f"{self.error_m * 1e3:.1f} mm")
        if self.share is not None:
            size.append(f"{self.share * 100:.0f}% of the error" if self.share <= 1 else f"share {self.share:g}")
        if self.confidence is not None:
            size.append(f"confidence {self.confidence:.2f}")
        if size:
            parts.append(", ".join(size))
        return "; ".join(parts) + "."


def _enum_text(value: Any) -> str:
    return str(getattr(value, "value", value))


def _format_estimate(value: Any) -> str:
    if isinstance(value, Mapping):
        return ", ".join(f"{k}={_format_estimate(v)}" for k, v in value.items())
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return _format_estimate(dataclasses.asdict(value))
    if isinstance(value, float | np.floating):
        return f"{float(value):.4g}"
    if isinstance(value, list | tuple | np.ndarray):
        return "[" + ", ".join(_format_estimate(v) for v in value) + "]"
    return _enum_text(value)


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
    findings: Sequence[Mapping[str, Any] | object] = (),
    reference_point: Sequence[float] | None = None,
    options: RerunOptions | None = None,
    env: Mapping[str, str] | None = None,
    notify: Callable[[str], None] | None = None,
) -> RerunOutcome:
    """Send one replay to ``target`` (save, connect or spawn), with the default blueprint.

    ``findings`` are the attribution engine's findings (objects or mappings with ``fault``, ``hop``,
    ``estimate``, ``share``, ``error_m``, ``evidence``, ``fix``); ``reference_point`` a declared
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
    blueprint = default_blueprint(result.frames)
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
        rows = log_replay(rec, timeline, result, findings=findings, reference_point=reference_point, options=opts)
        rec.flush(timeout_sec=60.0)
        rec.disconnect()
    except (RuntimeError, OSError) as err:
        where = str(chosen.path) if chosen.mode is OutputMode.SAVE else (chosen.url or "the default viewer")
        raise RerunSinkError(f"Rerun {chosen.mode.value} to {where} failed: {err}") from err
    return RerunOutcome(
        mode=chosen.mode, path=chosen.path if chosen.mode is OutputMode.SAVE else None,
        url=chosen.url, fell_back=fell_back, notes=tuple(notes), rows=rows,
    )


def default_blueprint(frames: ChainFrames) -> rrb.Blueprint:
    """3D view in the world frame (and all observations' world points), the camera's 2D view,
    the per-hop error and time-gap series, the text log."""
    import rerun.blueprint as rrb

    world = rrb.Spatial3DView(
        name=f"World ({frames.world})", origin="/",
        contents=["+ /**", "- /series/**", "- /log/**", "- /summary"],
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
    camera = rrb.Spatial2DView(
        name=f"Camera ({frames.camera})", origin="/camera",
        spatial_information=rrb.SpatialInformation(target_frame=frames.camera + IMAGE_PLANE_SUFFIX),
    )
    errors = rrb.TimeSeriesView(name="Per-hop error (mm)", origin="/series/error_mm")
    gaps = rrb.TimeSeriesView(name="Per-hop time gap (ms)", origin="/series/gap_ms")
    text = rrb.Vertical(
        rrb.TextLogView(name="Findings and rejections", origin="/log"),
        rrb.TextDocumentView(name="Summary", origin="/summary"),
        row_shares=[2, 1],
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(rrb.Tabs(world, history), text, row_shares=[3, 1]),
            rrb.Vertical(camera, errors, gaps, row_shares=[2, 1, 1]),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(state="expanded", timeline=SENSOR_TIME),
        collapse_panels=False,
    )


def log_replay(
    rec: rr.RecordingStream,
    timeline: Timeline,
    result: ReplayResult,
    *,
    findings: Sequence[Mapping[str, Any] | object] = (),
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
    as_run = as_run_points(timeline, result, match_tolerance_ns=opts.match_tolerance_ns,
                           reference_tolerance_ns=opts.reference_tolerance_ns)
    if reference_point is not None:
        declared = np.asarray(reference_point, dtype=float).reshape(3)
        have = _finite_rows(as_run.reference)
        reference = np.where(have[:, None], as_run.reference, declared)
        as_run = dataclasses.replace(as_run, reference=np.where(result.replayed[:, None], reference, np.nan))
        rec.log("/points/reference/declared",
                rr.Points3D([declared], colors=[REFERENCE_COLOR], radii=[opts.point_radius_m * 1.5],
                            labels=["declared reference"]),
                rr.CoordinateFrame(frames.world), static=True)
        rows["/points/reference/declared"] = 1
    _log_points(rec, result, as_run, opts, rows)
    _log_series(rec, result, as_run, rows)
    _log_text(rec, result, [FindingView.of(f) for f in findings], rows)
    return rows


# ----------------------------------------------------------------------------------------------
# As-run points


def as_run_points(
    timeline: Timeline,
    result: ReplayResult,
    *,
    match_tolerance_ns: int = POINT_MATCH_NS,
    reference_tolerance_ns: int = REFERENCE_MATCH_NS,
    buffer: TransformBuffer | None = None,
) -> AsRunPoints:
    """Match the robot's logged points to observations and express them in the chain frames.

    A point with ``obs_id >= 0`` belongs to that observation; one without is matched to the
    observation nearest in stamp within the tolerance (where several observations share that
    stamp, to the one whose recomputed point is nearest). Points logged in another frame than
    their hop's are transformed at their stamp with the log's transforms.
    """
    frames = result.frames
    recomputed = {"camera": result.p_cam, "body": result.p_body, "world": result.p_world}
    wanted = (
        ("camera", PointRole.HOP_CAMERA, frames.camera, match_tolerance_ns),
        ("body", PointRole.HOP_BODY, frames.body, match_tolerance_ns),
        ("world", PointRole.HOP_WORLD, frames.world, match_tolerance_ns),
        ("target", PointRole.TARGET, frames.world, match_tolerance_ns),
        ("reference", PointRole.REFERENCE, frames.world, reference_tolerance_ns),
    )
    cache: list[TransformBuffer] = [] if buffer is None else [buffer]

    def get_buffer() -> TransformBuffer:
        if not cache:
            cache.append(TransformBuffer.from_timeline(timeline))
        return cache[0]

    out: dict[str, FloatArray] = {}
    for leaf, role, frame, tolerance in wanted:
        points = timeline.points.with_role(role)
        xyz = _points_in_frame(points, frame, get_buffer)
        near = recomputed.get(leaf, result.p_world)
        out[leaf] = _match_to_observations(points, xyz, result, near, tolerance)
    return AsRunPoints(**out)


def _points_in_frame(points: PointTable, frame: str, get_buffer: Callable[[], TransformBuffer]) -> FloatArray:
    """Points (M, 3) expressed in ``frame`` at their stamps (NaN where no transform exists)."""
    xyz = points.xyz.astype(float, copy=True)
    target = normalize_frame(frame)
    for other in np.unique(points.frame):
        if not other or other == target:
            continue
        sel = points.frame == other
        lookup = get_buffer().lookup(target, str(other), points.stamp_ns[sel])
        moved = transform_points(lookup.translation, lookup.quat_xyzw, xyz[sel])
        moved[~lookup.ok] = np.nan
        xyz[sel] = moved
    return xyz


def _match_to_observations(
    points: PointTable, xyz: FloatArray, result: ReplayResult, recomputed: FloatArray, tolerance_ns: int
) -> FloatArray:
    """(N, 3) per observation: the matched point (the nearest in stamp when several match)."""
    obs = result.observations
    n = len(obs)
    out = np.full((n, 3), np.nan)
    if len(points) == 0 or n == 0:
        return out
    target = np.full(len(points), -1, dtype=np.int64)
    dt = np.zeros(len(points), dtype=np.int64)
    # By obs_id.
    order = np.argsort(obs.obs_id, kind="stable")
    has_id = points.obs_id >= 0
    if has_id.any():
        pos = np.clip(np.searchsorted(obs.obs_id[order], points.obs_id[has_id]), 0, n - 1)
        hit = obs.obs_id[order][pos] == points.obs_id[has_id]
        idx = np.flatnonzero(has_id)
        target[idx[hit]] = order[pos[hit]]
        dt[idx[hit]] = np.abs(points.stamp_ns[idx[hit]] - obs.stamp_ns[order[pos[hit]]])
    # By stamp.
    free = np.flatnonzero(~has_id)
    if free.size:
        by_stamp = np.argsort(obs.stamp_ns, kind="stable")
        stamps = obs.stamp_ns[by_stamp]
        pick = nearest(stamps, points.stamp_ns[free])
        gap = np.abs(stamps[pick] - points.stamp_ns[free])
        ok = gap <= tolerance_ns
        target[free[ok]] = by_stamp[pick[ok]]
        dt[free[ok]] = gap[ok]
        # Several observations on the nearest stamp: the one whose recomputed point is nearest.
        lo = np.searchsorted(stamps, stamps[pick], side="left")
        hi = np.searchsorted(stamps, stamps[pick], side="right")
        for k in np.flatnonzero(ok & (hi - lo > 1)):
            candidates = by_stamp[lo[k]:hi[k]]
            dist = np.linalg.norm(recomputed[candidates] - xyz[free[k]], axis=1)
            dist = np.where(np.isfinite(dist), dist, np.inf)
            target[free[k]] = candidates[int(np.argmin(dist))]
    matched = np.flatnonzero((target >= 0) & np.isfinite(xyz).all(axis=1))
    if matched.size == 0:
        return out
    # One point per observation: the nearest in stamp (ties: the later row).
    ranked = matched[np.lexsort((-matched, dt[matched]))]
    _, first = np.unique(target[ranked], return_index=True)
    chosen = ranked[first]
    out[target[chosen]] = xyz[chosen]
    return out


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
        rec.send_columns(
            "/camera/detections", indexes=_obs_indexes(result, every),
            columns=rr.Points2D.columns(
                positions=np.stack([obs.u, obs.v], axis=1), colors=colors.astype(np.uint8), labels=labels,
                radii=np.full(len(obs), 6.0),
            ),
        )
        rows["/camera/detections"] = len(obs)


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
    rec: rr.RecordingStream, result: ReplayResult, as_run: AsRunPoints, opts: RerunOptions, rows: dict[str, int]
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
            ),
        )
        rows[entity] = int(sel.size)

    for leaf in ("camera", "body", "world"):
        send_points(f"/points/recomputed/{leaf}", hop_frame[leaf], recomputed[leaf], RECOMPUTED_COLOR,
                    f"recomputed ({leaf})")
    for leaf in ("camera", "body", "world", "target"):
        logged = as_run.by_leaf(leaf)
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
    send_points("/points/reference/matched", frames.world, as_run.reference, REFERENCE_COLOR, "reference")


def _log_series(rec: rr.RecordingStream, result: ReplayResult, as_run: AsRunPoints, rows: dict[str, int]) -> None:
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
        err = np.linalg.norm(as_run.by_leaf(leaf) - recomputed[leaf], axis=1)
        sel = np.flatnonzero(ok & np.isfinite(err))
        send(f"/series/error_mm/{hop.value}", sel, err[sel] * 1e3, f"{hop.value} error (mm)", palette[hop])
    for leaf, color in (("target", AS_RUN_COLOR), ("reference", REFERENCE_COLOR)):
        err = np.linalg.norm(as_run.by_leaf(leaf) - result.p_world, axis=1)
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
    "AsRunPoints",
    "FindingView",
    "OutputMode",
    "RerunOptions",
    "RerunOutcome",
    "RerunSinkError",
    "RerunTarget",
    "as_run_points",
    "default_blueprint",
    "display_available",
    "log_replay",
    "resolve_target",
    "stream_replay",
    "summary_markdown",
]

