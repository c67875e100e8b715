"""The replay every later stage reads: one log through one chain, replayed once and its evidence aligned once.

Whether a static target is seen by bearing only (no depth in its detections, no depth frames) is
decided here, before the one replay: its observations are then replayed as rays at unit depth, and
their spread measured as how far the rays pass from one point
(:class:`~framechain.analysis.evidence.static.RayObjective`).
"""

from __future__ import annotations

from dataclasses import dataclass

from framechain.analysis.evidence.alignment import AlignedEvidence, align_evidence
from framechain.analysis.evidence.static import is_bearing_only, with_unit_depth
from framechain.catalogue import RejectReason
from framechain.config.chain import ChainConfig
from framechain.replay import ReplayResult, TransformBuffer, replay
from framechain.replay.rig import replay_rig
from framechain.timeline import Timeline


@dataclass(frozen=True)
class Replayed:
    """A timeline replayed through a chain: the frame graph, the replay, and the logged evidence aligned
    to every observation of the replay (all rows, in the chain's frames)."""

    timeline: Timeline  # as read (a bearing-only replay's unit depths are in ``replay.observations``)
    buffer: TransformBuffer
    replay: ReplayResult
    aligned: AlignedEvidence
    bearing_only: bool  # replayed as rays at unit depth
    notes: tuple[str, ...] = ()  # how it was replayed: rays, labels ignored


def bearing_only(timeline: Timeline, chain: ChainConfig) -> bool:
    """A static target with no depth source at all (and no other evidence): replayed as rays."""
    return (chain.evidence.static_target and not chain.evidence_topics() and chain.evidence.reference_point is None
            and not chain.is_rig and is_bearing_only(timeline, chain.frames.camera))


def replay_chain(timeline: Timeline, chain: ChainConfig, *, rays: bool = True) -> Replayed:
    """Replay ``timeline`` through ``chain`` once and align its logged points once.

    ``rays``: replay a bearing-only static target as rays at unit depth (what attribution needs);
    False replays the detections as they are (a bearing-only target then has no depth).
    """
    buffer = TransformBuffer.from_timeline(timeline)
    notes: list[str] = []
    as_rays = rays and bearing_only(timeline, chain)
    replayed_timeline = timeline
    if as_rays:
        replayed_timeline, n_rays = with_unit_depth(timeline, chain.frames.camera)
        notes.append(f"bearing only: no depth for {chain.frames.camera} (none in the detections, no depth frames); "
                     f"its {n_rays} observations are replayed as rays at unit depth and the static targets' spread "
                     "measured as how far their rays pass from one point")
    if chain.is_rig:
        result = replay_rig(replayed_timeline, chain.frames, chain.camera_frames(), buffer=buffer,
                            latency_budget_s=chain.latency_budget_s,
                            budgets_s={f: chain.latency_budget_for(f) for f in chain.camera_frames()},
                            ignore_labels=chain.evidence.ignore_labels)
    else:
        result = replay(replayed_timeline, chain.frames, buffer=buffer, latency_budget_s=chain.latency_budget_s,
                        ignore_labels=chain.evidence.ignore_labels)
    ignored = int((result.status == RejectReason.IGNORED_LABEL.value).sum())
    if ignored:
        notes.append(f"ignore_labels: {ignored} observations of labels {list(chain.evidence.ignore_labels)} "
                     "rejected as ignored_label (declared moving)")
    aligned = align_evidence(timeline.points, result.observations, chain.frames, buffer)
    return Replayed(timeline=timeline, buffer=buffer, replay=result, aligned=aligned, bearing_only=as_rays,
                    notes=tuple(notes))


__all__ = ["Replayed", "bearing_only", "replay_chain"]
