"""One evidence alignment: the robot's logged points matched to observations, in the chain's frames.

Every consumer of logged evidence (attribution, the Rerun sink, the reports) reads the result of
:func:`align_evidence`, so a point counts, or does not, in the same way everywhere.

Matching, per role (hop_camera, hop_body, hop_world, target, reference):

1. a point with ``obs_id >= 0`` belongs to the observation with that id;
2. an observation left without one takes, among the points without an id, those of the nearest
   stamp within the role's tolerance; several detections of one image (equal stamps) take that
   stamp's points in order: the k-th detection the k-th point (points ordered by log time).

Each matched point is then moved from its ``frame_id`` into the frame its hop needs (hop_camera:
the chain's camera frame, hop_body: the body, hop_world/target/reference: the world) with the
log's transforms at the POINT's stamp (tf2's ``lookupTransform(target, source, stamp)``). Where
nothing matches, or the transform is unavailable, the observation gets NaN; every point ends up
in exactly one counted reason.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from enum import StrEnum

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray, IntArray, distinct_names, rows_of
from framechain.config.chain import ChainFrames
from framechain.geometry.transforms import transform_points
from framechain.replay import TransformBuffer
from framechain.replay.stamps import nearest
from framechain.timeline import ObservationTable, PointRole, PointTable, normalize_frame

#: A point stamped with the observation's stamp matches within this (ns).
POINT_MATCH_NS = 1_000_000
#: A reference stream sample (motion capture) matches an observation within this (ns).
REFERENCE_MATCH_NS = 50_000_000
#: Every role, in chain order.
ROLES: tuple[PointRole, ...] = (
    PointRole.HOP_CAMERA, PointRole.HOP_BODY, PointRole.HOP_WORLD, PointRole.TARGET, PointRole.REFERENCE,
)


class PointFate(StrEnum):
    """What became of one logged point (each point has exactly one)."""

    BY_OBS_ID = "matched_by_obs_id"
    BY_STAMP = "matched_by_stamp"
    NO_OBSERVATION = "no_observation"  # no observation with its obs_id, or none stamped within the tolerance
    EXTRA = "extra"  # its observation already has a point (more points than detections at that stamp)
    NO_TRANSFORM = "no_transform"  # matched, but its frame could not be brought into the hop's frame


def role_frame(role: PointRole, frames: ChainFrames) -> str:
    """The chain frame a role's points are compared in."""
    if role is PointRole.HOP_CAMERA:
        return frames.camera
    if role is PointRole.HOP_BODY:
        return frames.body
    return frames.world


def role_tolerance_ns(role: PointRole) -> int:
    return REFERENCE_MATCH_NS if role is PointRole.REFERENCE else POINT_MATCH_NS


@dataclass(frozen=True)
class RoleAlignment:
    """One role's points, one row per observation, in the chain frame of the role."""

    role: PointRole
    frame: str
    xyz: FloatArray  # (N, 3); NaN where no point matched or its transform was unavailable
    point_row: IntArray  # (N,) row of the matched point in the role's PointTable, -1 for none
    fates: Mapping[PointFate, int]  # per fate, over the role's points (they add up to its point count)
    n_points: int

    @property
    def used(self) -> int:
        return int(np.isfinite(self.xyz).all(axis=1).sum())

    def take(self, rows: IntArray) -> RoleAlignment:
        return replace(self, xyz=self.xyz[rows], point_row=self.point_row[rows])


@dataclass(frozen=True)
class AlignedEvidence:
    """The logged evidence of every role aligned to a list of observations (N rows, in their order)."""

    obs_id: IntArray
    roles: Mapping[PointRole, RoleAlignment]
    notes: tuple[str, ...] = ()

    def __len__(self) -> int:
        return int(self.obs_id.size)

    def points(self, role: PointRole) -> FloatArray:
        """(N, 3) points of ``role`` in its chain frame, NaN where none."""
        return self.roles[role].xyz

    def present(self, role: PointRole) -> bool:
        """Whether any observation has a point of ``role``."""
        return self.roles[role].used > 0

    def take(self, rows: npt.ArrayLike) -> AlignedEvidence:
        """A subset of the observations (e.g. the replayed ones)."""
        index = np.asarray(rows, dtype=np.int64)
        return replace(self, obs_id=self.obs_id[index], roles={r: a.take(index) for r, a in self.roles.items()})

    def counts(self) -> dict[str, dict[str, int]]:
        """Per role with points: how many points met each fate, and how many observations got one."""
        out: dict[str, dict[str, int]] = {}
        for role, a in self.roles.items():
            if a.n_points:
                out[role.value] = {"points": a.n_points, **{f.value: n for f, n in a.fates.items() if n},
                                   "observations_with_a_point": a.used}
        return out


def align_evidence(
    points: PointTable,
    observations: ObservationTable,
    frames: ChainFrames,
    buffer: TransformBuffer,
    *,
    tolerances_ns: Mapping[PointRole, int] | None = None,
) -> AlignedEvidence:
    """Align every role of ``points`` to ``observations`` (see the module docstring)."""
    tolerances = {role: role_tolerance_ns(role) for role in ROLES}
    tolerances.update(tolerances_ns or {})
    obs_id = np.asarray(observations.obs_id, dtype=np.int64)
    stamps = np.asarray(observations.stamp_ns, dtype=np.int64)
    roles: dict[PointRole, RoleAlignment] = {}
    notes: list[str] = []
    stamp_matched = False
    for role in ROLES:
        table = points.with_role(role)
        target = role_frame(role, frames)
        alignment, row_notes = _align_role(role, table, obs_id, stamps, target, buffer, tolerances[role])
        roles[role] = alignment
        notes += row_notes
        stamp_matched |= alignment.fates.get(PointFate.BY_STAMP, 0) > 0
    shared = stamps.size - np.unique(stamps).size
    if stamp_matched and shared:
        notes.append(f"{shared} observations share a stamp with another; logged points were matched to them in "
                     "order within each stamp")
    return AlignedEvidence(obs_id=obs_id, roles=roles, notes=tuple(notes))


def _align_role(
    role: PointRole,
    table: PointTable,
    obs_id: IntArray,
    stamps: IntArray,
    target: str,
    buffer: TransformBuffer,
    tolerance_ns: int,
) -> tuple[RoleAlignment, list[str]]:
    n, m = stamps.size, len(table)
    fates = dict.fromkeys(PointFate, 0)
    if m == 0 or n == 0:
        fates[PointFate.NO_OBSERVATION] = m
        empty = RoleAlignment(role, target, np.full((n, 3), np.nan), np.full(n, -1, dtype=np.int64), fates, m)
        return empty, []
    point_row = _match(table, obs_id, stamps, tolerance_ns)
    matched = point_row >= 0
    by_id = np.zeros(m, dtype=bool)
    by_id[point_row[matched]] = table.obs_id[point_row[matched]] >= 0
    assigned = np.zeros(m, dtype=bool)
    assigned[point_row[matched]] = True
    xyz = np.full((n, 3), np.nan)
    xyz[matched] = _in_frame(table.take(point_row[matched]), target, buffer)
    moved = np.isfinite(xyz).all(axis=1)
    fates[PointFate.BY_OBS_ID] = int((by_id[point_row[matched]] & moved[matched]).sum())
    fates[PointFate.BY_STAMP] = int((~by_id[point_row[matched]] & moved[matched]).sum())
    fates[PointFate.NO_TRANSFORM] = int((~moved[matched]).sum())
    # The points no observation took: none near (or no such obs_id), or one too many for its observation.
    free = np.flatnonzero(~assigned)
    order = np.argsort(stamps, kind="stable")
    near = np.zeros(free.size, dtype=bool)
    if free.size:
        gap = np.abs(stamps[order][nearest(stamps[order], table.stamp_ns[free])] - table.stamp_ns[free])
        has_id = table.obs_id[free] >= 0
        near = np.where(has_id, np.isin(table.obs_id[free], obs_id), gap <= tolerance_ns)
    fates[PointFate.EXTRA] = int(near.sum())
    fates[PointFate.NO_OBSERVATION] = int((~near).sum())
    alignment = RoleAlignment(role, target, xyz, np.where(matched, point_row, -1), fates, m)
    unmoved = sorted(set(table.frame[point_row[matched & ~moved]].tolist()))
    return alignment, _notes(alignment, table, stamps, tolerance_ns, unmoved)


def _match(table: PointTable, obs_id: IntArray, stamps: IntArray, tolerance_ns: int) -> IntArray:
    """(N,) row of ``table`` matched to each observation, -1 for none (obs_id first, then stamp and rank)."""
    n = stamps.size
    out = np.full(n, -1, dtype=np.int64)
    # 1. By obs_id: the first point logged for the observation.
    with_id = np.flatnonzero(table.obs_id >= 0)
    with_id = with_id[np.argsort(table.log_time_ns[with_id], kind="stable")]
    row = rows_of(table.obs_id[with_id], obs_id)
    out[row >= 0] = with_id[row[row >= 0]]
    # 2. By stamp and rank within equal stamps, for observations still without a point.
    free = np.flatnonzero(table.obs_id < 0)
    if free.size:
        free = free[np.lexsort((free, table.log_time_ns[free], table.stamp_ns[free]))]
        point_stamps = table.stamp_ns[free]
        group_stamps, group_start, group_size = np.unique(point_stamps, return_index=True, return_counts=True)
        group = nearest(group_stamps, stamps)
        rank = _rank_within_equal(stamps)
        ok = (out < 0) & (np.abs(group_stamps[group] - stamps) <= tolerance_ns) & (rank < group_size[group])
        out[ok] = free[group_start[group[ok]] + rank[ok]]
    return out


def _rank_within_equal(values: IntArray) -> IntArray:
    """For each element, how many earlier elements have the same value (0 for the first)."""
    order = np.argsort(values, kind="stable")
    sorted_values = values[order]
    starts = np.flatnonzero(np.r_[True, sorted_values[1:] != sorted_values[:-1]])
    run = np.repeat(starts, np.diff(np.r_[starts, sorted_values.size]))
    rank = np.empty_like(values)
    rank[order] = np.arange(values.size) - run
    return rank


def _in_frame(points: PointTable, target: str, buffer: TransformBuffer) -> FloatArray:
    """Points (M, 3) moved into ``target`` at their own stamps; NaN where no transform is available.

    A point without a frame_id is taken to be in ``target`` already.
    """
    xyz = np.asarray(points.xyz, dtype=float).copy()
    frame = normalize_frame(target)
    for other in distinct_names(points.frame):
        if not other or other == frame:
            continue
        sel = points.frame == other
        lookup = buffer.lookup(frame, str(other), points.stamp_ns[sel])
        moved = transform_points(lookup.translation, lookup.quat_xyzw, xyz[sel])
        moved[~lookup.ok] = np.nan
        xyz[sel] = moved
    return xyz


def _notes(
    alignment: RoleAlignment, table: PointTable, stamps: IntArray, tolerance_ns: int, unmoved: list[str]
) -> list[str]:
    """Say when logged evidence did not line up with the observations (it is then not used)."""
    notes: list[str] = []
    topics = ", ".join(sorted(set(table.source.tolist()) - {""})) or alignment.role.value
    fates = alignment.fates
    unmatched = fates[PointFate.NO_OBSERVATION]
    if unmatched and alignment.used < min(alignment.n_points, stamps.size):
        order = np.sort(stamps)
        gaps = np.abs(order[nearest(order, table.stamp_ns)] - table.stamp_ns)
        notes.append(
            f"{alignment.role.value} points on {topics}: {alignment.used} of {stamps.size} observations matched a "
            f"point stamped within {tolerance_ns / 1e6:g} ms of the detection's stamp (median offset of the points "
            f"{np.median(gaps) / 1e6:.1f} ms); log them with the detection's header.stamp"
        )
    if fates[PointFate.NO_TRANSFORM]:
        notes.append(
            f"{alignment.role.value} points on {topics}: {fates[PointFate.NO_TRANSFORM]} matched an observation but "
            f"could not be moved from {', '.join(unmoved)} into {alignment.frame} at their stamps (no transform "
            "there); they are not used"
        )
    return notes


__all__ = [
    "POINT_MATCH_NS",
    "REFERENCE_MATCH_NS",
    "ROLES",
    "AlignedEvidence",
    "PointFate",
    "RoleAlignment",
    "align_evidence",
    "role_frame",
]
