"""The hop-by-hop replay: every observation through pixel_to_camera, camera_to_body, body_to_world.

All hops run on whole arrays of observations. Every observation ends replayed or rejected with
one :class:`RejectReason`; ``stale`` marks replayed observations whose transform samples lie
further from the observation stamp than the latency budget. Totals reconcile:
``replayed + sum(rejected.values()) == total``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from framechain.arrays import BoolArray, FloatArray, IntArray, StrArray
from framechain.catalogue import HopName, NothingReplayed, RejectReason
from framechain.config.chain import ChainFrames
from framechain.geometry.camera import CameraModel, distinct_models
from framechain.geometry.transforms import transform_points
from framechain.replay.buffer import LookupResult, LookupStatus, TransformBuffer
from framechain.replay.depth import sample_depth
from framechain.timeline import CameraTable, Column, ColumnTable, ObservationTable, Timeline, normalize_frame

#: Status string of an observation that went through every hop.
REPLAYED = "replayed"


@dataclass(frozen=True)
class HopRecordTable(ColumnTable):
    """One row per observation and hop: input, output, transform used, its samples and the gap.

    ``sample_before_ns``/``sample_after_ns`` are the stamps of the samples used on the hop's
    stalest dynamic edge (for pixel_to_camera: the depth frame's stamp); ``gap_ns`` is the
    observation stamp minus the nearest of them (0 when every edge is static). ``status`` is
    ``replayed`` or the rejection reason of the observation.
    """

    COLUMNS: ClassVar[dict[str, Column]] = {
        "obs_id": Column("i8"),
        "hop": Column("str"),
        "from_frame": Column("str"),
        "to_frame": Column("str"),
        "stamp_ns": Column("i8"),
        "input_xyz": Column("f8", (3,)),
        "output_xyz": Column("f8", (3,)),
        "translation": Column("f8", (3,)),
        "quat_xyzw": Column("f8", (4,)),
        "sample_before_ns": Column("i8"),
        "sample_after_ns": Column("i8"),
        "gap_ns": Column("i8"),
        "stale": Column("bool"),
        "status": Column("str"),
    }
    obs_id: IntArray
    hop: StrArray
    from_frame: StrArray
    to_frame: StrArray
    stamp_ns: IntArray
    input_xyz: FloatArray
    output_xyz: FloatArray
    translation: FloatArray
    quat_xyzw: FloatArray
    sample_before_ns: IntArray
    sample_after_ns: IntArray
    gap_ns: IntArray
    stale: BoolArray
    status: StrArray


@dataclass(frozen=True)
class HopSampleTable(ColumnTable):
    """One row per observation, hop and edge of the hop's path: the transform samples it used.

    ``HopRecordTable`` keeps the stalest edge of a hop; this keeps every edge (map -> odom and
    odom -> base_link both, for a body_to_world hop), with the gap from the observation stamp to
    each of the two samples interpolated between (``gap_*_ns = observation stamp - sample stamp``;
    static edges are timeless: their gaps are 0). Rows of rejected observations are kept, with
    ``status`` saying why, so the table joins the hop records on ``(obs_id, hop)``.
    """

    COLUMNS: ClassVar[dict[str, Column]] = {
        "obs_id": Column("i8"),
        "hop": Column("str"),
        "parent": Column("str"),
        "child": Column("str"),
        "static": Column("bool"),
        "sample_before_ns": Column("i8"),
        "sample_after_ns": Column("i8"),
        "weight": Column("f8"),
        "gap_before_ns": Column("i8"),
        "gap_after_ns": Column("i8"),
        "status": Column("str"),
    }
    obs_id: IntArray
    hop: StrArray
    parent: StrArray
    child: StrArray
    static: BoolArray
    sample_before_ns: IntArray
    sample_after_ns: IntArray
    weight: FloatArray
    gap_before_ns: IntArray
    gap_after_ns: IntArray
    status: StrArray


@dataclass(frozen=True)
class ReplayOptions:
    """Knobs of one replay. Offsets shift when each transform is looked up (fault models use them).

    ``pose_offset_ns``: body_to_world is looked up at ``stamp + pose_offset_ns``;
    ``camera_offset_ns``: camera_to_body at ``stamp + camera_offset_ns`` (a wrist camera).
    ``tolerance_ns`` allows the nearest sample just outside a span (reported as stale).
    """

    pose_offset_ns: int = 0
    camera_offset_ns: int = 0
    tolerance_ns: int = 0
    depth_window: int = 5
    max_depth_gap_ns: int = 50_000_000


@dataclass(frozen=True)
class ReplayResult:
    """Every observation through the chain, as arrays (one row per observation) and hop records."""

    frames: ChainFrames
    observations: ObservationTable
    status: StrArray  # "replayed" or a RejectReason value
    stale: BoolArray
    depth_m: FloatArray
    depth_stamp_ns: IntArray
    ray: FloatArray  # (N, 3) undistorted [x, y, 1]
    #: (N,) row of ``timeline.cameras`` in force for each observation (-1: none), the model its pixel was
    #: undistorted with unless ``cameras`` overrode it
    camera_row: IntArray
    p_cam: FloatArray  # (N, 3) NaN where rejected
    p_body: FloatArray
    p_world: FloatArray
    body_from_cam: LookupResult
    world_from_body: LookupResult
    hops: HopRecordTable
    samples: HopSampleTable
    latency_budget_ns: int
    options: ReplayOptions = field(default_factory=ReplayOptions)
    #: detections the reader could not turn into observations (no intrinsics, PnP failed, ...), by
    #: reason: they have no row here but count in :meth:`counts`, so every detection is accounted for
    rejected_at_read: Mapping[str, int] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.status.shape[0])

    @property
    def replayed(self) -> BoolArray:
        out: BoolArray = self.status == REPLAYED
        return out

    def counts(self) -> dict[str, object]:
        """``{"total", "replayed", "rejected": {reason: n}, "stale"}``; the totals reconcile.

        Detections rejected while the log was read are in ``total`` and ``rejected`` too.
        """
        reasons, n = np.unique(self.status[~self.replayed], return_counts=True)
        rejected = {str(r): int(c) for r, c in zip(reasons, n, strict=True)}
        for reason, count in self.rejected_at_read.items():
            rejected[reason] = rejected.get(reason, 0) + int(count)
        return {
            "total": len(self) + sum(int(c) for c in self.rejected_at_read.values()),
            "replayed": int(self.replayed.sum()),
            "rejected": rejected,
            "stale": int((self.stale & self.replayed).sum()),
        }

    def nothing_replayed(self) -> NothingReplayed | None:
        """Why no observation was replayed, every rejection counted by reason (None when some were)."""
        if self.replayed.any():
            return None
        reasons, n = np.unique(self.status, return_counts=True)
        return NothingReplayed(
            total=len(self) + sum(int(c) for c in self.rejected_at_read.values()),
            rejected={RejectReason(str(r)): int(c) for r, c in zip(reasons, n, strict=True)},
            rejected_at_read=dict(self.rejected_at_read),
        )

    def main_camera_row(self) -> int | None:
        """The row of the camera table most replayed observations were seen through (None: none)."""
        rows = self.camera_row[self.replayed]
        rows = rows[rows >= 0]
        if rows.size == 0:
            return None
        values, counts = np.unique(rows, return_counts=True)
        return int(values[np.argmax(counts)])


def camera_rows_for(cameras: CameraTable, frame: str, stamps_ns: IntArray) -> IntArray:
    """Row of ``cameras`` in force at each stamp for ``frame`` (-1 where there is none).

    The latest CameraInfo at or before the stamp; before the first one, the first (intrinsics
    rarely change, and a log often starts with the image before the first CameraInfo).
    """
    mine = np.flatnonzero(cameras.frame == normalize_frame(frame))
    if mine.size == 0:
        return np.full(stamps_ns.shape[0], -1, dtype=np.int64)
    order = mine[np.argsort(cameras.stamp_ns[mine], kind="stable")]
    pos = np.searchsorted(cameras.stamp_ns[order], stamps_ns, side="right") - 1
    return order[np.clip(pos, 0, order.size - 1)].astype(np.int64)


def replay(
    timeline: Timeline,
    frames: ChainFrames,
    *,
    buffer: TransformBuffer | None = None,
    latency_budget_s: float = 0.02,
    options: ReplayOptions | None = None,
    cameras: Mapping[str, CameraModel] | None = None,
    ignore_labels: Sequence[str] = (),
) -> ReplayResult:
    """Replay every observation of ``timeline`` through the chain ``frames``.

    ``buffer`` defaults to one built from the timeline's transforms (pass it to replay the same
    log many times); ``cameras`` overrides the recorded intrinsics per frame (fault models);
    observations labelled with one of ``ignore_labels`` are rejected as ``ignored_label``.
    """
    opts = options or ReplayOptions()
    buf = buffer if buffer is not None else TransformBuffer.from_timeline(timeline)
    obs = timeline.observations
    status = _Status(len(obs))
    # An observation of another camera of this log is not this chain's to replay.
    other_cameras = set(np.unique(timeline.cameras.frame).tolist()) - {frames.camera}
    if other_cameras:
        status.reject(np.isin(obs.camera_frame, sorted(other_cameras)), RejectReason.OTHER_CAMERA)
    if ignore_labels:
        status.reject(np.isin(obs.label, list(ignore_labels)), RejectReason.IGNORED_LABEL)
    ray, camera_row = _rays(timeline, frames.camera, status, cameras)  # hop 1: pixel_to_camera
    depth = _depths(timeline, frames.camera, status, opts)
    p_cam = ray * np.where(np.isfinite(depth.depth_m), depth.depth_m, np.nan)[:, None]  # (0 * Inf would warn)
    # Hops 2 and 3: transforms at the observation stamp (plus any offset a fault model asks for).
    body_from_cam = buf.lookup(frames.body, frames.camera, obs.stamp_ns + opts.camera_offset_ns,
                               tolerance_ns=opts.tolerance_ns)
    world_from_body = buf.lookup(frames.world, frames.body, obs.stamp_ns + opts.pose_offset_ns,
                                 tolerance_ns=opts.tolerance_ns)
    for lookup in (body_from_cam, world_from_body):
        status.reject(lookup.status == LookupStatus.NO_PATH, RejectReason.MISSING_EDGE)
        status.reject(~lookup.ok, RejectReason.EXTRAPOLATION)
    ok = status.live
    p_cam[~ok] = np.nan
    p_body = transform_points(body_from_cam.translation, body_from_cam.quat_xyzw, p_cam)
    p_world = transform_points(world_from_body.translation, world_from_body.quat_xyzw, p_body)
    status_str = status.codes.astype(str)
    hops, stale = _records(obs, frames, depth, (p_cam, p_body, p_world), (body_from_cam, world_from_body),
                           round(latency_budget_s * 1e9), status_str)
    samples = HopSampleTable.concat([
        _sample_rows(obs, HopName.CAMERA_TO_BODY, body_from_cam, status_str),
        _sample_rows(obs, HopName.BODY_TO_WORLD, world_from_body, status_str),
    ])
    return ReplayResult(
        frames=frames, observations=obs, status=status_str, stale=stale & ok, depth_m=depth.depth_m,
        depth_stamp_ns=depth.stamp_ns, ray=ray, camera_row=camera_row, p_cam=p_cam, p_body=p_body,
        p_world=p_world, body_from_cam=body_from_cam, world_from_body=world_from_body, hops=hops, samples=samples,
        latency_budget_ns=round(latency_budget_s * 1e9), options=opts,
        rejected_at_read={str(k): int(v) for k, v in dict(timeline.metadata.get("rejected_at_read", {})).items()},
    )


class _Status:
    """Each observation's status: ``replayed`` until the first reason rejects it."""

    def __init__(self, n: int) -> None:
        self.codes = np.full(n, REPLAYED, dtype=object)

    @property
    def live(self) -> BoolArray:
        out: BoolArray = self.codes == REPLAYED
        return out

    def reject(self, mask: BoolArray, reason: RejectReason) -> None:
        self.codes[mask & self.live] = reason.value


def _rays(
    timeline: Timeline, camera_frame: str, status: _Status, cameras: Mapping[str, CameraModel] | None
) -> tuple[FloatArray, IntArray]:
    """Hop 1: each live observation's undistorted ray [x, y, 1] (NaN elsewhere), and the row of the camera
    table in force at its stamp; rejects the observations without a camera model or outside the image."""
    obs = timeline.observations
    n = len(obs)
    ray = np.full((n, 3), np.nan)
    inside = np.zeros(n, dtype=bool)
    rows = camera_rows_for(timeline.cameras, camera_frame, obs.stamp_ns)
    if cameras is not None and camera_frame in cameras:
        models = [cameras[camera_frame]]
        model_row = np.zeros(n, dtype=np.int64)
    else:
        status.reject(rows < 0, RejectReason.NO_CAMERA_INFO)
        models, model_of = distinct_models(timeline.cameras, rows[rows >= 0])
        model_row = np.zeros(n, dtype=np.int64)
        model_row[rows >= 0] = model_of
    # Observations grouped by camera model in one sort (a mask per model is quadratic: a CameraInfo
    # per frame makes as many models as observations).
    live = np.flatnonzero(status.live)
    by_model = live[np.argsort(model_row[live], kind="stable")]
    for sel in np.split(by_model, np.flatnonzero(np.diff(model_row[by_model])) + 1) if by_model.size else []:
        model = models[int(model_row[sel[0]])]
        inside[sel] = model.inside(obs.u[sel], obs.v[sel])
        x, y = model.pixel_to_normalized(obs.u[sel], obs.v[sel])
        ray[sel] = np.stack([x, y, np.ones_like(x)], axis=1)
    status.reject(~inside, RejectReason.OUTSIDE_IMAGE)
    return ray, rows


@dataclass(frozen=True)
class _Depths:
    depth_m: FloatArray  # (N,) the detection's own depth, else sampled from a depth frame
    stamp_ns: IntArray  # (N,) where the depth came from (the observation or the depth frame)
    has_source: BoolArray  # (N,) a depth was given or a depth frame found (a stamp of 0 is a valid stamp)


def _depths(timeline: Timeline, camera_frame: str, status: _Status, opts: ReplayOptions) -> _Depths:
    """Each observation's depth; rejects those without one (no depth frame near) or with an invalid one."""
    obs = timeline.observations
    depth = obs.depth_m.copy()
    depth_stamp = np.where(np.isfinite(depth), obs.stamp_ns, 0)
    has_source = np.isfinite(depth)
    need = np.isnan(depth) & status.live  # NaN: not given, sample it; +-Inf is given and invalid
    if need.any():
        sampled = sample_depth(
            timeline.depth_frames, camera_frame, obs.stamp_ns[need], obs.u[need], obs.v[need],
            max_gap_ns=opts.max_depth_gap_ns, window=opts.depth_window,
        )
        depth[need] = sampled.depth_m
        depth_stamp[need] = sampled.stamp_ns
        has_source[need] = sampled.frame_index >= 0
        status.reject(need & ~has_source, RejectReason.NO_DEPTH)
    status.reject(~np.isfinite(depth) | (depth <= 0), RejectReason.DEPTH_INVALID)
    return _Depths(depth, depth_stamp, has_source)


def _records(
    obs: ObservationTable, frames: ChainFrames, depth: _Depths, points: tuple[FloatArray, FloatArray, FloatArray],
    lookups: tuple[LookupResult, LookupResult], budget_ns: int, status: StrArray,
) -> tuple[HopRecordTable, BoolArray]:
    """One record per observation and hop, and whether each observation is stale (any sample, or its depth
    frame, further from its stamp than the budget; or a transform taken from just outside its span)."""
    n = len(obs)
    p_cam, p_body, p_world = points
    body_from_cam, world_from_body = lookups
    depth_gap = np.where(depth.has_source, obs.stamp_ns - depth.stamp_ns, 0)
    gap_cam, before_cam, after_cam = _stalest(body_from_cam, obs.stamp_ns)
    gap_world, before_world, after_world = _stalest(world_from_body, obs.stamp_ns)
    stale_cam = np.abs(gap_cam) > budget_ns
    stale_world = np.abs(gap_world) > budget_ns
    stale_depth = np.abs(depth_gap) > budget_ns
    stale = (stale_cam | stale_world | stale_depth | (body_from_cam.status == LookupStatus.NEAREST)
             | (world_from_body.status == LookupStatus.NEAREST))
    hops = HopRecordTable.concat([
        _hop_rows(obs, HopName.PIXEL_TO_CAMERA, "pixel", frames.camera,
                  np.stack([obs.u, obs.v, depth.depth_m], axis=1), p_cam, np.zeros((n, 3)),
                  np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), depth.stamp_ns, depth.stamp_ns, depth_gap, stale_depth,
                  status),
        _hop_rows(obs, HopName.CAMERA_TO_BODY, frames.camera, frames.body, p_cam, p_body,
                  body_from_cam.translation, body_from_cam.quat_xyzw, before_cam, after_cam, gap_cam,
                  stale_cam, status),
        _hop_rows(obs, HopName.BODY_TO_WORLD, frames.body, frames.world, p_body, p_world,
                  world_from_body.translation, world_from_body.quat_xyzw, before_world, after_world,
                  gap_world, stale_world, status),
    ])
    return hops, stale


def _sample_rows(
    obs: ObservationTable, hop: HopName, lookup: LookupResult, status: StrArray
) -> HopSampleTable:
    """Every edge of ``lookup``'s path, for every observation (edge-major, as lookups keep them)."""
    n = len(obs)
    tables = []
    for h in lookup.hops:
        static = h.hop.is_static
        zeros = np.zeros(n, dtype=np.int64)
        tables.append(HopSampleTable(
            obs_id=obs.obs_id, hop=np.full(n, hop.value), parent=np.full(n, h.hop.parent),
            child=np.full(n, h.hop.child), static=np.full(n, static), sample_before_ns=h.stamp_before_ns,
            sample_after_ns=h.stamp_after_ns, weight=h.weight,
            gap_before_ns=zeros if static else obs.stamp_ns - h.stamp_before_ns,
            gap_after_ns=zeros if static else obs.stamp_ns - h.stamp_after_ns, status=status,
        ))
    return HopSampleTable.concat(tables) if tables else HopSampleTable.empty()


def _stalest(lookup: LookupResult, stamps_ns: IntArray) -> tuple[IntArray, IntArray, IntArray]:
    """Per observation: the largest |gap| over the dynamic edges used, and that edge's samples.

    Gaps are taken against the observation stamp, not the shifted time a fault model asked for.
    """
    dynamic = [h for h in lookup.hops if not h.hop.is_static]
    n = stamps_ns.shape[0]
    if not dynamic:
        zeros = np.zeros(n, dtype=np.int64)
        return zeros, zeros.copy(), zeros.copy()
    before = np.stack([h.stamp_before_ns for h in dynamic])
    after = np.stack([h.stamp_after_ns for h in dynamic])
    near = np.where(np.abs(stamps_ns - before) <= np.abs(after - stamps_ns), before, after)
    gaps = stamps_ns - near
    k = np.argmax(np.abs(gaps), axis=0)
    cols = np.arange(n)
    return gaps[k, cols], before[k, cols], after[k, cols]


def _hop_rows(
    obs: ObservationTable, hop: HopName, from_frame: str, to_frame: str, inp: FloatArray, out: FloatArray,
    translation: FloatArray, quat: FloatArray, before: IntArray, after: IntArray, gap: IntArray,
    stale: BoolArray, status: StrArray,
) -> HopRecordTable:
    n = len(obs)
    return HopRecordTable(
        obs_id=obs.obs_id, hop=np.full(n, hop.value), from_frame=np.full(n, from_frame),
        to_frame=np.full(n, to_frame), stamp_ns=obs.stamp_ns, input_xyz=inp, output_xyz=out,
        translation=translation, quat_xyzw=quat, sample_before_ns=before, sample_after_ns=after,
        gap_ns=gap, stale=stale, status=status,
    )
