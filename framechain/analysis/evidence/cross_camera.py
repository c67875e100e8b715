"""Cross-camera evidence: sightings of one label by two or more cameras of a rig must land on one point.

Two kinds of agreement, on disjoint observations:

- **same instant** (moving labels; every label when the rig has no pose): a sighting of a label by one
  camera is compared with another camera's track of the same label at the same instant, interpolated
  linearly between that camera's two sightings around it (at most 1.5 frames apart; an exact stamp is
  used as it is, and where the track starts, ends or skips, its nearest sighting within one frame).
  With a pose the points are compared in the world, without one in the rig's body frame
  (``frames.world`` is then the body). A camera whose stamps are off by ``d`` is compared with the
  others' tracks at the instant it really saw the label once its offset is applied: the brackets are
  searched again for every offset tried.
- **static labels at any time** (a rig with a pose): each (label, window) object's world points, from
  every camera that saw it, are measured against the object's fitted position, as for one camera
  (:mod:`~framechain.analysis.evidence.static`); on a fixed rig only objects seen by several cameras count (a
  fixed camera over a fixed tag shows nothing of its own chain).

:class:`CrossCameraObjective` returns one residual per observation (its own point minus the mean of the
other cameras' interpolated points, or minus its object's fitted position), NaN for an observation
compared with nothing. It evaluates the whole rig under a perturbation and picks the rows it is asked
for by ``obs_id``, so a subset of rows (a bootstrap resample, a grid's subsample) keeps its partners.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import NamedTuple

import numpy as np

from framechain.analysis.evidence.static import StaticGroups, fit_static_points
from framechain.analysis.model.chain import ChainInputs, Perturbation, evaluate
from framechain.arrays import BoolArray, FloatArray, IntArray, StrArray

#: A partner's two sightings around the instant compared may be this many of its frame periods apart.
MAX_GAP_FRAMES = 1.5
#: A partner's sighting this close to the instant (s) is used as it is, without a bracket.
SAME_STAMP_S = 1e-3
#: A camera's frame period is this percentile of the steps between its stamps (it may see nothing in many frames).
FRAME_PERCENTILE = 5.0


class Brackets(NamedTuple):
    """For each compared pair: the partner's two track rows around the instant and the weight of the second."""

    valid: BoolArray  # (P,)
    before: IntArray  # (P,) rows of the rig's inputs
    after: IntArray
    weight: FloatArray  # (P,) of ``after``


@dataclass(frozen=True)
class PairIndex:
    """Which sightings are compared at the same instant: each anchor row with another camera's track of the
    same label (rows of the rig's inputs sorted by track, then stamp)."""

    anchor: IntArray  # (P,) the row compared
    partner: IntArray  # (P,) the other camera's index
    code: IntArray  # (P,) the partner's track: label code * cameras + camera
    track_rows: IntArray  # (T,) rows sorted by (code, stamp)
    track_key: IntArray  # (T,) code * stride + stamp - t0
    stride: int
    t0: int
    max_gap_ns: IntArray  # (K,) per camera
    same_ns: int

    @property
    def size(self) -> int:
        return int(self.anchor.shape[0])

    def brackets(self, inputs: ChainInputs, offsets_ns: IntArray, *, strict: bool = False) -> Brackets:
        """Each pair's partner sightings around the anchor's instant, every camera's stamps shifted by its
        offset (``offsets_ns``, one per camera). ``strict``: only sightings within a frame of the instant;
        otherwise a pair whose track has moved away keeps its nearest sighting (a pair is made strictly, at
        no offset, and then compared under every offset tried: the fit sees a continuous error, never a
        pair appearing or vanishing)."""
        index = _camera_index(inputs)
        shift = offsets_ns[index[self.anchor]] - offsets_ns[self.partner]
        query = inputs.stamp_ns[self.anchor] + shift - self.t0
        base = self.code * self.stride
        key = base + query
        pos = np.searchsorted(self.track_key, key, side="left")
        n = self.track_key.shape[0]
        j2 = np.minimum(pos, n - 1)
        j1 = np.maximum(pos - 1, 0)
        t2 = self.track_key[j2] - base
        t1 = self.track_key[j1] - base
        has2 = (pos < n) & (t2 >= 0) & (t2 < self.stride)
        has1 = (pos > 0) & (t1 >= 0) & (t1 < self.stride)
        period = self.max_gap_ns[self.partner] / MAX_GAP_FRAMES
        exact2 = has2 & (t2 - query <= self.same_ns)
        exact1 = has1 & ~exact2 & (query - t1 <= self.same_ns)
        gap = t2 - t1
        between = has1 & has2 & ~exact1 & ~exact2 & (gap <= self.max_gap_ns[self.partner])
        # No bracket (the track starts, ends or skips here): the nearest sighting within a frame stands for it.
        reach = period if strict else np.inf
        near2 = has2 & ~exact1 & ~exact2 & ~between & (t2 - query <= reach) & (~has1 | (t2 - query <= query - t1))
        near1 = has1 & ~exact1 & ~exact2 & ~between & ~near2 & (query - t1 <= reach)
        weight = np.where(between, (query - t1) / np.maximum(gap, 1), 0.0)
        second = exact2 | near2
        before = np.where(second, j2, j1)
        after = np.where(between, j2, before)
        return Brackets(exact1 | exact2 | between | near1 | near2, self.track_rows[before], self.track_rows[after],
                        weight)


def _camera_index(inputs: ChainInputs) -> IntArray:
    if inputs.camera_index is None:
        return np.zeros(len(inputs), dtype=np.int64)
    return inputs.camera_index


def frame_periods_ns(inputs: ChainInputs) -> IntArray:
    """Each rig camera's frame period: a low percentile of the steps between its distinct stamps (ns; 1 s if it
    has none)."""
    index = _camera_index(inputs)
    out = np.full(max(len(inputs.rig_cameras), 1), 1_000_000_000, dtype=np.int64)
    for k in range(out.size):
        stamps = np.unique(inputs.stamp_ns[index == k])
        if stamps.size > 1:  # a camera sees tags in some frames only: its shortest steps are one frame
            out[k] = int(np.percentile(np.diff(stamps), FRAME_PERCENTILE))
    return out


def pair_index(inputs: ChainInputs, labels: StrArray, compared: BoolArray) -> PairIndex:
    """Every pair of a ``compared`` row and another camera's track of its label that holds a sighting at the
    row's instant (within about one frame time)."""
    index = _camera_index(inputs)
    k = max(len(inputs.rig_cameras), 1)
    _names, label_code = np.unique(np.asarray(labels, dtype=str), return_inverse=True)
    code = label_code.astype(np.int64) * k + index
    mine = np.flatnonzero(compared)
    first = int(inputs.stamp_ns.min()) if len(inputs) else 0
    span = int(inputs.stamp_ns.max()) - first + 1 if len(inputs) else 1
    # Keys code * stride + time: a span of room either side keeps every shifted instant in its track's range.
    t0, stride = first - span, 3 * span + 1
    if (int(code.max(initial=0)) + 1) * stride >= 2**62:
        t0, stride = first, span + 1
    order = mine[np.lexsort((inputs.stamp_ns[mine], code[mine]))]
    periods = frame_periods_ns(inputs)
    anchor = np.repeat(mine, k)
    partner = np.tile(np.arange(k, dtype=np.int64), mine.size)
    keep = partner != index[anchor]
    anchor, partner = anchor[keep], partner[keep]
    pairs = PairIndex(
        anchor=anchor, partner=partner, code=label_code[anchor].astype(np.int64) * k + partner, track_rows=order,
        track_key=code[order] * stride + (inputs.stamp_ns[order] - t0), stride=stride, t0=t0,
        max_gap_ns=(periods * MAX_GAP_FRAMES).astype(np.int64),
        same_ns=int(min(SAME_STAMP_S * 1e9, 0.1 * float(periods.min()))),
    )
    valid = pairs.brackets(inputs, np.zeros(k, dtype=np.int64), strict=True).valid
    return PairIndex(anchor[valid], partner[valid], pairs.code[valid], pairs.track_rows, pairs.track_key, stride,
                     t0, pairs.max_gap_ns, pairs.same_ns)


@dataclass(frozen=True)
class CrossCameraObjective:
    """Residuals of a rig's observations against the other cameras' sightings (see the module docstring).

    ``rig`` is every replayed observation of the rig; ``static`` groups the rows measured against their
    static object (unused rows -1), ``pairs`` the same-instant comparisons; ``range_m`` each camera's
    recorded median range, by which its static residuals are rescaled (a camera's depths scaled towards
    it shrink its objects' spread without explaining it). ``timeless_pose``: the rig's pose does not change
    with time (fixed, or none), so a camera's stamp offset moves none of its points, only which sightings
    are compared: the points of the last perturbation are kept and reused.
    """

    rig: ChainInputs
    static: StaticGroups
    pairs: PairIndex
    range_m: FloatArray  # (K,)
    timeless_pose: bool = False
    _kept: dict[str, object] = field(default_factory=dict, compare=False, repr=False)

    def __call__(self, inputs: ChainInputs, pert: Perturbation) -> FloatArray:
        return self.residuals(pert)[self._rows(inputs)]

    def take(self, index: IntArray) -> CrossCameraObjective:
        """The same objective: it picks the rows it is called with by their ``obs_id``."""
        return self

    def over(self, rig: ChainInputs) -> CrossCameraObjective:
        """The same comparisons (pairs, static objects, ranges) over other observations of the same rows (``rig``:
        this rig's inputs with other pixels or depths, as the bounds write noise-free or faulty ones)."""
        return replace(self, rig=rig, _kept={})

    def restamped(self, shifts_ns: dict[int, int]) -> CrossCameraObjective:
        """The same comparisons with rig camera ``k``'s stamps moved by ``shifts_ns[k]`` (a stamping fault written
        into the log's own detections; each track keeps its order, shifted as a whole)."""
        index = _camera_index(self.rig)
        shift = np.zeros(len(self.rig), dtype=np.int64)
        for k, ns in shifts_ns.items():
            shift[index == k] = ns
        rig = replace(self.rig, stamp_ns=self.rig.stamp_ns + shift)
        pairs = replace(self.pairs, track_key=self.pairs.track_key + shift[self.pairs.track_rows])
        return replace(self, rig=rig, pairs=pairs, _kept={})

    def consensus(self, pert: Perturbation) -> FloatArray:
        """(N, 3) where every observation of the rig would be if the cameras agreed under ``pert``: its static
        object's fitted position; for a sighting compared at the same instant with ``n`` others, the mean of its
        own point and theirs (its point minus ``n / (n + 1)`` of its residual: a pair meets half-way); its own
        point when it is compared with nothing."""
        _p_cam, p, static = self._points(pert)
        out = p.copy()
        if static is not None:
            out[self.static.used] = p[self.static.used] - static
        if self.pairs.size:
            rows, mean = self._pair_means(p, pert)
            slot = self._anchors[1]
            n = np.bincount(slot, self._partners(p, pert)[2].astype(float), minlength=rows.size)
            held = np.isfinite(mean).all(axis=1)
            out[rows[held]] = p[rows[held]] - (n[held] / (n[held] + 1.0))[:, None] * mean[held]
        return out

    @cached_property
    def _id_order(self) -> tuple[IntArray, IntArray]:
        order = np.argsort(self.rig.obs_id, kind="stable")
        return order, self.rig.obs_id[order]

    @cached_property
    def _anchors(self) -> tuple[IntArray, IntArray]:
        """The rows compared at the same instant, and each pair's index among them."""
        rows, slot = np.unique(self.pairs.anchor, return_inverse=True)
        return rows, slot.astype(np.int64)

    def _rows(self, inputs: ChainInputs) -> IntArray:
        order, ids = self._id_order
        pos = np.clip(np.searchsorted(ids, inputs.obs_id), 0, max(ids.size - 1, 0))
        if ids.size == 0 or not np.array_equal(ids[pos], inputs.obs_id):
            raise ValueError("observations that are not the rig's")
        out: IntArray = order[pos]
        return out

    def residuals(self, pert: Perturbation) -> FloatArray:
        """(N, 3) residual of every observation of the rig under ``pert`` (NaN: compared with nothing)."""
        p_cam, p, static = self._points(pert)
        out = np.full((len(self.rig), 3), np.nan)
        if static is not None:
            out[self.static.used] = static * self._range_scale(p_cam, pert)[self.static.used, None]
        if self.pairs.size:
            rows, mean = self._pair_means(p, pert)
            out[rows] = mean
        return out

    def _points(self, pert: Perturbation) -> tuple[FloatArray, FloatArray, FloatArray | None]:
        """Camera-frame and compared points under ``pert`` and the static rows' residuals (kept for the next
        call when only stamp offsets change on a timeless pose)."""
        key = _points_key(pert, self.timeless_pose)
        if self._kept.get("key") == key:
            return self._kept["p_cam"], self._kept["p"], self._kept["static"]  # type: ignore[return-value]
        p_cam, _, p = evaluate(self.rig, pert)
        static = None
        if self.static.used.any():
            used = self.static.used
            static = (p - fit_static_points(p, self.static))[used]
        self._kept.update(key=key, p_cam=p_cam, p=p, static=static)
        return p_cam, p, static

    def _pair_means(self, p: FloatArray, pert: Perturbation) -> tuple[IntArray, FloatArray]:
        """Each compared row and its point minus the mean of its partners' (NaN where none holds)."""
        rows, slot = self._anchors
        _anchor, partner_points, valid = self._partners(p, pert)
        diff = np.where(valid[:, None], p[self.pairs.anchor] - partner_points, 0.0)
        counts = np.bincount(slot, valid.astype(float), minlength=rows.size)
        sums = np.stack([np.bincount(slot, diff[:, j], minlength=rows.size) for j in range(3)], axis=1)
        mean = np.where((counts > 0)[:, None], sums / np.maximum(counts, 1.0)[:, None], np.nan)
        return rows, mean

    def points(self, inputs: ChainInputs, pert: Perturbation) -> FloatArray:
        """What each observation is measured against: its static object's fitted position, or the mean of the
        other cameras' points at its instant (NaN: nothing)."""
        _p_cam, p, static = self._points(pert)
        out = np.full((len(self.rig), 3), np.nan)
        if static is not None:
            out[self.static.used] = p[self.static.used] - static
        if self.pairs.size:
            rows, mean = self._pair_means(p, pert)
            out[rows] = p[rows] - mean
        return out[self._rows(inputs)]

    def partners(self, pert: Perturbation) -> tuple[IntArray, IntArray, FloatArray]:
        """Each same-instant comparison under ``pert`` that holds: (anchor row, partner camera, the partner's
        interpolated point); rows of the rig's inputs."""
        p = self._points(pert)[1]
        anchor, points, valid = self._partners(p, pert)
        return anchor[valid], self.pairs.partner[valid], points[valid]

    def _partners(self, p: FloatArray, pert: Perturbation) -> tuple[IntArray, FloatArray, BoolArray]:
        k = max(len(self.rig.rig_cameras), 1)
        offsets = np.zeros(k, dtype=np.int64)
        for camera, delta in pert.cameras.items():
            offsets[camera] = round(delta.offset_s * 1e9)
        b = self.pairs.brackets(self.rig, offsets)
        points = (1.0 - b.weight)[:, None] * p[b.before] + b.weight[:, None] * p[b.after]
        valid = b.valid & np.isfinite(points).all(axis=1) & np.isfinite(p[self.pairs.anchor]).all(axis=1)
        return self.pairs.anchor, points, valid

    def _range_scale(self, p_cam: FloatArray, pert: Perturbation) -> FloatArray:
        """Per row: its camera's recorded median range over its median range now (1 for unused cameras, and for
        every camera when the perturbation leaves the pixels and depths alone)."""
        index = _camera_index(self.rig)
        scale = np.ones(self.range_m.shape[0])
        if not _moves_points_along_rays(pert):
            out: FloatArray = scale[index]
            return out
        ranges = np.linalg.norm(p_cam, axis=1)
        for k in range(scale.size):
            mine = (index == k) & self.static.used & np.isfinite(ranges)
            if mine.any() and self.range_m[k] > 0:
                scale[k] = self.range_m[k] / max(float(np.median(ranges[mine])), 1e-9)
        scaled: FloatArray = scale[index]
        return scaled


def _moves_points_along_rays(pert: Perturbation) -> bool:
    """Whether a perturbation changes the camera-frame points (depth or intrinsics scales)."""
    return (pert.depth_factor != 1.0 or pert.focal_scale != 1.0 or pert.principal_scale != 1.0
            or any(d.depth_factor != 1.0 or d.focal_scale != 1.0 for d in pert.cameras.values()))


def _points_key(pert: Perturbation, timeless_pose: bool) -> tuple[object, ...]:
    """What of a perturbation the rig's points depend on (a camera's stamp offset not, on a timeless pose)."""
    fields_: list[object] = [pert.focal_scale, pert.principal_scale, pert.depth_factor,
                             np.asarray(pert.rotvec_mount, dtype=float).tobytes(),
                             None if pert.permutation is None else np.asarray(pert.permutation).tobytes(),
                             pert.invert_camera, pert.invert_edge, pert.camera_offset_s, pert.pose_offset_s,
                             pert.invert_pose, pert.world, pert.camera_frame, pert.body_frame]
    for k, d in sorted(pert.cameras.items()):
        fields_.append((k, np.asarray(d.rotvec_mount, dtype=float).tobytes(),
                        np.asarray(d.translation_m, dtype=float).tobytes(), 0.0 if timeless_pose else d.offset_s,
                        d.focal_scale, d.depth_factor))
    return tuple(fields_)


def camera_ranges(inputs: ChainInputs) -> FloatArray:
    """Each rig camera's median range to what it saw (m; 0 when it saw nothing)."""
    index = _camera_index(inputs)
    ranges = np.linalg.norm(inputs.ray * inputs.depth_m[:, None], axis=1)
    out = np.zeros(max(len(inputs.rig_cameras), 1))
    for k in range(out.size):
        mine = (index == k) & np.isfinite(ranges)
        if mine.any():
            out[k] = float(np.median(ranges[mine]))
    return out


__all__ = ["Brackets", "CrossCameraObjective", "PairIndex", "camera_ranges", "frame_periods_ns", "pair_index"]
