"""A rig's replay: every camera's observations through its own chain (its frame, its latency budget), in one
:class:`ReplayResult` whose rows are the timeline's observations in their order.

Each camera is replayed with :func:`~framechain.replay.replay.replay` on its own observations (the
transform lookups of one camera's path run once, vectorised); the results are put back in the
observations' order. An observation of a frame that is none of the rig's cameras is rejected as
``other_camera``. The merged ``body_from_cam`` lookup holds each row's own camera's transform; its
per-edge samples live in the hop records and the sample table (``hops`` is empty: the paths differ).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any, TypeVar

import numpy as np

from framechain.arrays import IntArray
from framechain.catalogue import HopName, RejectReason
from framechain.config.chain import ChainFrames
from framechain.geometry.camera import CameraModel
from framechain.replay.buffer import LookupResult, TransformBuffer
from framechain.replay.replay import HopRecordTable, HopSampleTable, ReplayOptions, ReplayResult, replay
from framechain.timeline import ObservationTable, Timeline, normalize_frame

_HOP_RANK = {hop.value: k for k, hop in enumerate(HopName)}
_Table = TypeVar("_Table", HopRecordTable, HopSampleTable)


def replay_rig(
    timeline: Timeline,
    frames: ChainFrames,
    cameras: Sequence[str],
    *,
    buffer: TransformBuffer | None = None,
    latency_budget_s: float = 0.02,
    budgets_s: Mapping[str, float] | None = None,
    options: ReplayOptions | None = None,
    models: Mapping[str, CameraModel] | None = None,
    ignore_labels: Sequence[str] = (),
) -> ReplayResult:
    """Replay every observation of ``timeline`` through the chain of its camera (one of ``cameras``, the rig's
    optical frames; ``frames.camera`` is the first). ``budgets_s`` gives a camera its own latency budget."""
    buf = buffer if buffer is not None else TransformBuffer.from_timeline(timeline)
    obs = timeline.observations
    budgets = dict(budgets_s or {})
    parts: list[tuple[IntArray, ReplayResult]] = []
    mine = np.zeros(len(obs), dtype=bool)
    for frame in cameras:
        rows = np.flatnonzero(obs.camera_frame == normalize_frame(frame))
        mine[rows] = True
        part = replay(timeline.replace(observations=obs.take(rows)), replace(frames, camera=frame), buffer=buf,
                      latency_budget_s=budgets.get(frame, latency_budget_s), options=options, cameras=models,
                      ignore_labels=ignore_labels)
        parts.append((rows, part))
    others = np.flatnonzero(~mine)
    if others.size:  # not the rig's: replayed through the first camera's chain only to be rejected
        part = replay(timeline.replace(observations=obs.take(others)), frames, buffer=buf,
                      latency_budget_s=latency_budget_s, options=options, cameras=models)
        parts.append((others, _rejected(part, RejectReason.OTHER_CAMERA)))
    merged = _merge(parts, frames, len(obs))
    rejected_at_read = {str(k): int(v) for k, v in dict(timeline.metadata.get("rejected_at_read", {})).items()}
    return replace(merged, latency_budget_ns=round(latency_budget_s * 1e9), rejected_at_read=rejected_at_read)


def _rejected(result: ReplayResult, reason: RejectReason) -> ReplayResult:
    """Every row of ``result`` rejected with ``reason`` (its points NaN)."""
    n = len(result)
    status = np.full(n, reason.value, dtype=object).astype(str)
    nan = np.full((n, 3), np.nan)
    hops = replace(result.hops, status=np.full(len(result.hops), reason.value).astype(str),
                   stale=np.zeros(len(result.hops), dtype=bool))
    samples = replace(result.samples, status=np.full(len(result.samples), reason.value).astype(str))
    return replace(result, status=status, stale=np.zeros(n, dtype=bool), p_cam=nan, p_body=nan.copy(),
                   p_world=nan.copy(), hops=hops, samples=samples)


def _merge(parts: list[tuple[IntArray, ReplayResult]], frames: ChainFrames, n: int) -> ReplayResult:
    """One result from the cameras' results (each over its rows of the observations), in the observations' order."""
    rows = np.concatenate([r for r, _ in parts]) if parts else np.zeros(0, dtype=np.int64)
    order = np.argsort(rows, kind="stable")  # position in the concatenation of each observation

    def cat(name: str) -> Any:
        return np.concatenate([getattr(p, name) for _, p in parts])[order]

    results = [p for _, p in parts]
    first = results[0]
    observations = ObservationTable.concat([p.observations for p in results]).take(order)
    by_id = dict(zip(observations.obs_id.tolist(), range(n), strict=True))
    hops = _in_order(HopRecordTable.concat([p.hops for p in results]), by_id)
    samples = _in_order(HopSampleTable.concat([p.samples for p in results]), by_id)
    return replace(
        first, frames=frames, observations=observations, status=cat("status"), stale=cat("stale"),
        depth_m=cat("depth_m"), depth_stamp_ns=cat("depth_stamp_ns"), ray=cat("ray"), camera_row=cat("camera_row"),
        p_cam=cat("p_cam"), p_body=cat("p_body"), p_world=cat("p_world"),
        body_from_cam=_merged_lookup([p.body_from_cam for p in results], order, frames.body, frames.camera),
        world_from_body=_merged_lookup([p.world_from_body for p in results], order, frames.world, frames.body),
        hops=hops, samples=samples,
    )


def _in_order(table: _Table, by_id: Mapping[int, int]) -> _Table:
    """Rows sorted hop by hop, then by the observation's row (the order of a one-camera replay)."""
    if not len(table):
        return table
    row = np.array([by_id[i] for i in table.obs_id.tolist()], dtype=np.int64)
    rank = np.array([_HOP_RANK[h] for h in table.hop.tolist()], dtype=np.int64)
    return table.take(np.lexsort((row, rank)))


def _merged_lookup(lookups: list[LookupResult], order: IntArray, target: str, source: str) -> LookupResult:
    """Each row's own lookup (per-row arrays concatenated); no per-edge samples (the cameras' paths differ)."""
    first = lookups[0]
    return replace(
        first, target=target, source=source,
        times_ns=np.concatenate([lk.times_ns for lk in lookups])[order],
        translation=np.concatenate([lk.translation for lk in lookups])[order],
        quat_xyzw=np.concatenate([lk.quat_xyzw for lk in lookups])[order],
        status=np.concatenate([lk.status for lk in lookups])[order], hops=(),
    )


__all__ = ["replay_rig"]
