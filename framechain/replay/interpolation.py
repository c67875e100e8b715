"""Sampling one dynamic edge at many times: the lookup hot path (tf2 cache semantics, vectorised).

An :class:`Interpolant` lays an edge's samples out for random access; a lookup cuts its query times
into chunks of :data:`CHUNK`, and each chunk is sampled into :class:`HopBuffers` rows with the
scratch rows of one :class:`Workspace`, allocated once per lookup.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray, IntArray
from framechain.geometry.rotations import quat_conjugate, quat_multiply
from framechain.replay.samples import Edge, HopSamples, LookupStatus, PathHop

#: Times per chunk of a lookup: big enough that NumPy's per-call cost vanishes, small enough that
#: the chunk's scratch rows stay in cache.
CHUNK = 1 << 14
#: Bucket index: buckets per sample, and the most samples a refinement may step over before a
#: plain binary search is cheaper (irregular stamps).
_BUCKETS_PER_SAMPLE = 1
_MAX_BUCKET_STEPS = 4
#: Smallest slerp angle used as a divisor: below it slerp and lerp agree to 1e-24.
_MIN_HALF_ANGLE = 1e-12
_INT64_MAX = np.iinfo(np.int64).max
_INT64_MIN = np.iinfo(np.int64).min
# Scratch rows of a chunk's workspace: 0-2 sampling; the rest composing (see Workspace.composing).
_SCRATCH_ROWS = 25
_PAIR_A_T, _PAIR_A_Q = slice(3, 6), slice(6, 10)
_PAIR_B_T, _PAIR_B_Q = slice(10, 13), slice(13, 17)
_SCRATCH = slice(17, 22)
_DELTA = slice(22, 25)


# Columns of an interpolant's rows (one row per sample; row i describes samples i and i + 1).
_T, _STEP, _Q, _QN, _HALF, _SIN = slice(0, 3), slice(3, 6), slice(6, 10), slice(10, 14), 14, 15
_N_COLS = 16  # 128 bytes: two cache lines per gathered row


@dataclass(frozen=True)
class Interpolant:
    """Tables of one dynamic edge for the lookup hot path, laid out for random access.

    ``rows`` (m, 16) holds per sample ``i``: the translation, the step to the next translation, the
    quaternion, the next quaternion on the short arc, the half-angle ``W`` between them and its sine.
    The last row stands for the newest sample itself with a zero step, so an exact hit on it needs
    no special case. One 128-byte row per time is gathered (two cache lines, not a miss per column:
    random query times make these gathers the main cost). Slerp is ``q(w) = a q_i + b q_(i+1)``
    with ``b = sin(w W) / sin W`` and ``a = cos(w W) - cos W b``: at ``w = 0`` exactly ``q_i``, so an
    exact stamp returns the sample bit for bit. The weight is ``(t - t_i) / (t_(i+1) - t_i)`` in
    integer nanoseconds, as tf2.

    The sample at or before each time comes from buckets of equal width over the recorded span:
    ``buckets`` row ``k`` holds the index ``j`` of the last sample before bucket ``k`` and the stamps of
    samples ``j .. j + steps + 1``; counting those at or before the time gives the index, and the
    row also holds the stamps of the samples used. Stamps too irregular for a few steps fall back to
    a binary search.
    """

    stamps: IntArray  # (m,)
    first_ns: int
    last_ns: int
    rows: FloatArray  # (m, 16), 64-byte aligned
    stamps_padded: IntArray  # (m + 2,) int64 min, the stamps, int64 max
    buckets: IntArray | None  # (n_buckets + 1, 4 or 8), 64-byte aligned; None: binary search
    bucket_origin: float
    bucket_scale: float
    bucket_top: float
    bucket_steps: int
    small_steps: bool  # no two consecutive samples are more than 90 degrees apart

    @classmethod
    def of(cls, edge: Edge) -> Interpolant:
        stamps = edge.stamps_ns
        m = stamps.shape[0]
        trans = edge.translation_soa
        quat = edge.quat_soa
        quat_next = quat.copy()
        quat_next[:, :-1] = quat[:, 1:]
        dot = np.einsum("ij,ij->j", quat[:, :-1], quat[:, 1:])
        quat_next[:, :-1] *= np.where(dot < 0, -1.0, 1.0)
        rel = quat_multiply(quat_conjugate(quat), quat_next)  # q_i^-1 q_(i+1), w >= 0
        half = np.maximum(np.arctan2(np.sqrt(rel[0] ** 2 + rel[1] ** 2 + rel[2] ** 2), np.abs(rel[3])),
                          _MIN_HALF_ANGLE)
        rows = _aligned_empty((m, _N_COLS), np.float64)
        rows[...] = 0.0
        rows[:, _T] = trans.T
        rows[:-1, _STEP] = np.diff(trans, axis=1).T
        rows[:, _Q] = quat.T
        rows[:, _QN] = quat_next.T
        rows[:, _HALF] = half
        rows[:, _SIN] = np.sin(half)
        first, last = int(stamps[0]), int(stamps[-1])
        buckets: IntArray | None = None
        origin, scale, top, steps = float(first), 0.0, 0.0, 0
        if m >= 2 and float(last) > origin:  # (stamps a few ns apart may be one float64 apart)
            n_buckets = _BUCKETS_PER_SAMPLE * m
            top = float(n_buckets)
            scale = n_buckets / (float(last) - origin)
            of_stamp = _bucket(stamps, origin, scale, top)
            ids = np.arange(n_buckets + 1)
            lowest = np.searchsorted(of_stamp, ids, side="left") - 1  # samples surely before the bucket
            highest = np.searchsorted(of_stamp, ids, side="right") - 1  # samples possibly in it
            steps = int((highest - lowest).max())
            if steps <= _MAX_BUCKET_STEPS:
                ext = np.concatenate([[_INT64_MIN], stamps, np.full(steps + 1, _INT64_MAX)])
                buckets = _aligned_empty((n_buckets + 1, 4 if steps <= 1 else 8), np.int64)  # 32 or 64 bytes
                buckets[...] = 0
                buckets[:, 0] = lowest
                for j in range(steps + 2):
                    buckets[:, 1 + j] = ext[lowest + 1 + j]
        return cls(
            stamps=stamps, first_ns=first, last_ns=last, rows=rows,
            stamps_padded=np.concatenate([[_INT64_MIN], stamps, [_INT64_MAX]]).astype(np.int64),
            buckets=buckets, bucket_origin=origin, bucket_scale=scale, bucket_top=top, bucket_steps=steps,
            small_steps=bool(half.max() <= np.pi / 4),
        )

    def index_into(self, t: IntArray, lo: IntArray, before: IntArray, after: IntArray, ws: Workspace) -> None:
        """``lo`` = the sample at or before each time (-1: none), ``before``/``after`` = its and the next stamp."""
        c = t.shape[0]
        if self.buckets is None:
            np.subtract(np.searchsorted(self.stamps, t, side="right"), 1, out=lo)
            np.add(lo, 1, out=ws.i[0])
            np.take(self.stamps_padded, ws.i[0], out=before, mode="clip")
            ws.i[0] += 1
            np.take(self.stamps_padded, ws.i[0], out=after, mode="clip")
            return
        f = ws.f[0]
        np.copyto(f, t, casting="unsafe")
        np.subtract(f, self.bucket_origin, out=f)
        np.multiply(f, self.bucket_scale, out=f)
        np.clip(f, 0.0, self.bucket_top, out=f)
        probe = ws.i[0]
        np.copyto(probe, f, casting="unsafe")
        width = self.buckets.shape[1]
        rows = ws.bucket_rows(width)
        np.take(self.buckets, probe, axis=0, out=rows, mode="clip")
        count = ws.i[1]
        count[...] = 0
        for j in range(self.bucket_steps):
            np.less_equal(rows[:, 2 + j], t, out=ws.mask)
            count += ws.mask
        np.add(rows[:, 0], count, out=lo)
        flat = rows.reshape(-1)
        np.multiply(ws.arange[:c], width, out=probe)
        probe += count
        probe += 1
        np.take(flat, probe, out=before, mode="clip")
        probe += 1
        np.take(flat, probe, out=after, mode="clip")

    def sample_into(self, t: IntArray, tolerance_ns: int, out: HopViews, ws: Workspace) -> bool:
        """Fill ``out`` for the times ``t`` (one chunk); True when some time is not plainly inside the span."""
        lo = ws.lo
        self.index_into(t, lo, out.before, out.after, ws)
        outside = bool(t.shape[0]) and (int(t.min()) < self.first_ns or int(t.max()) > self.last_ns)
        if outside:
            past = t < self.first_ns
            np.maximum(lo, 0, out=lo)
            out.before[past] = self.first_ns
        g = ws.gathered
        np.take(self.rows, lo, axis=0, out=g, mode="clip")
        dt, span = ws.i[1], ws.i[0]
        np.subtract(t, out.before, out=dt)
        np.subtract(out.after, out.before, out=span)  # > 0 inside the span (the newest: int64 max - stamp)
        weight = out.weight
        if outside:
            with np.errstate(divide="ignore", invalid="ignore"):
                np.divide(dt, span, out=weight)
        else:
            np.divide(dt, span, out=weight)
        if outside:
            future = t > self.last_ns
            out.status[past] = LookupStatus.EXTRAPOLATED_PAST
            out.status[future] = LookupStatus.EXTRAPOLATED_FUTURE
            if tolerance_ns > 0:
                near = (past & (self.first_ns - t <= tolerance_ns)) | (future & (t - self.last_ns <= tolerance_ns))
                out.status[near] = LookupStatus.NEAREST
            weight[past | future] = 0.0  # the oldest or newest sample itself
        np.equal(weight, 0.0, out=ws.mask)
        np.copyto(out.after, out.before, where=ws.mask)  # exact hits and single samples: one stamp
        f1 = ws.f[0]
        for k in range(3):
            np.multiply(g[:, 3 + k], weight, out=f1)
            np.add(g[:, k], f1, out=out.translation[k])
        self._slerp_into(g, weight, out, ws)
        if not outside:
            return False
        bad = out.status > LookupStatus.NEAREST
        if bad.any():
            out.translation[:, bad] = np.nan
            out.quat[:, bad] = np.nan
        return True

    def _slerp_into(self, g: FloatArray, weight: FloatArray, out: HopViews, ws: Workspace) -> None:
        """``out.quat``: each time's rotation, ``weight`` of the way from its sample before to the one after
        (``g``: each time's gathered row, with both samples' quaternions and the half angle between them)."""
        f1, f2, f3 = ws.f[0], ws.f[1], ws.f[2]
        np.multiply(g[:, _HALF], weight, out=f1)
        np.sin(f1, out=f2)
        sin_half = g[:, _SIN]
        if self.small_steps:  # cos = sqrt(1 - sin^2): exact to an ulp while the angle is below pi/4
            np.multiply(f2, f2, out=f3)
            np.subtract(1.0, f3, out=f3)
            np.sqrt(f3, out=f3)  # cos(w W)
            np.multiply(sin_half, sin_half, out=f1)
            np.subtract(1.0, f1, out=f1)
            np.sqrt(f1, out=f1)  # cos W
        else:
            np.cos(f1, out=f3)
            np.cos(g[:, _HALF], out=f1)
        np.divide(f2, sin_half, out=f2)  # b
        f1 *= f2
        np.subtract(f3, f1, out=f3)  # a = cos(w W) - cos W b
        for k in range(4):
            row = out.quat[k]
            np.multiply(g[:, 6 + k], f3, out=row)
            np.multiply(g[:, 10 + k], f2, out=f1)
            row += f1


def _aligned_empty(shape: tuple[int, int], dtype: type[np.generic], align: int = 64) -> npt.NDArray[Any]:
    """An uninitialised C-ordered array whose data starts on a cache-line boundary."""
    itemsize = np.dtype(dtype).itemsize
    count = shape[0] * shape[1]
    raw = np.empty(count + align // itemsize, dtype=dtype)
    skip = (-raw.ctypes.data % align) // itemsize
    out: npt.NDArray[Any] = raw[skip : skip + count].reshape(shape)
    return out


def _bucket(t: IntArray, origin: float, scale: float, top: float) -> IntArray:
    """Bucket of each time: monotone in t, the same arithmetic as :meth:`Interpolant.index_into`."""
    f = t.astype(np.float64)
    np.subtract(f, origin, out=f)
    np.multiply(f, scale, out=f)
    np.clip(f, 0.0, top, out=f)
    return f.astype(np.int64)


@dataclass(frozen=True)
class HopViews:
    """Rows of one chunk in a hop's output buffers."""

    before: IntArray
    after: IntArray
    weight: FloatArray
    status: npt.NDArray[np.uint8]
    translation: FloatArray  # (3, c)
    quat: FloatArray  # (4, c)


class HopBuffers:
    """The output arrays of one dynamic hop over a whole lookup, filled chunk by chunk."""

    def __init__(self, n: int) -> None:
        self.before = np.empty(n, dtype=np.int64)
        self.after = np.empty(n, dtype=np.int64)
        self.weight = np.empty(n)
        self.status = np.zeros(n, dtype=np.uint8)
        self.translation = np.empty((3, n))
        self.quat = np.empty((4, n))

    def view(self, sl: slice) -> HopViews:
        return HopViews(self.before[sl], self.after[sl], self.weight[sl], self.status[sl],
                         self.translation[:, sl], self.quat[:, sl])

    def samples(self, hop: PathHop, t: IntArray, edge: Edge) -> HopSamples:
        return HopSamples(
            hop=hop, times_ns=t, stamp_before_ns=self.before, stamp_after_ns=self.after, weight=self.weight,
            status=self.status, translation_soa=self.translation, quat_soa=self.quat, first_ns=edge.first_ns,
            last_ns=edge.last_ns,
        )


class Workspace:
    """Scratch rows for one chunk, allocated once per lookup and reused by every chunk."""

    def __init__(self, size: int, *, _parent: Workspace | None = None) -> None:
        self.size = size
        if _parent is None:
            self._f = np.empty((_SCRATCH_ROWS, size))
            self._i = np.empty((3, size), dtype=np.int64)
            self._mask = np.empty(size, dtype=bool)
            self._gathered = _aligned_empty((size, _N_COLS), np.float64)
            self._buckets: dict[int, IntArray] = {}
            self.arange = np.arange(size, dtype=np.int64)
        else:
            self._f, self._i, self._mask = _parent._f, _parent._i, _parent._mask
            self._gathered, self._buckets, self.arange = _parent._gathered, _parent._buckets, _parent.arange
        self.f = self._f[:, :size]
        self.i = self._i[:, :size]
        self.lo = self.i[2]
        self.mask = self._mask[:size]
        self.gathered = self._gathered[:size]

    def bucket_rows(self, width: int) -> IntArray:
        """A (size, width) block for gathered bucket rows."""
        block = self._buckets.get(width)
        if block is None:
            block = self._buckets[width] = _aligned_empty((self._gathered.shape[0], width), np.int64)
        return block[: self.size]

    def sized(self, size: int) -> Workspace:
        """This workspace cut to a (last, shorter) chunk."""
        return self if size == self.size else Workspace(size, _parent=self)

    def composing(self) -> tuple[FloatArray, FloatArray, tuple[tuple[FloatArray, FloatArray], ...]]:
        """The rows composing uses: scratch (5, c), a delta (3, c) and two (translation, quaternion) pairs."""
        f = self.f
        return f[_SCRATCH], f[_DELTA], ((f[_PAIR_A_T], f[_PAIR_A_Q]), (f[_PAIR_B_T], f[_PAIR_B_Q]))


def static_samples(hop: PathHop, edge: Edge, t: IntArray) -> HopSamples:
    """A static hop at every time: broadcast views of its one sample."""
    n = t.shape[0]
    stamp = np.broadcast_to(np.int64(edge.first_ns), (n,))
    return HopSamples(
        hop=hop, times_ns=t, stamp_before_ns=stamp, stamp_after_ns=stamp,
        weight=np.broadcast_to(0.0, (n,)), status=np.zeros(n, dtype=np.uint8),
        translation_soa=np.broadcast_to(edge.translation_soa[:, :1], (3, n)),
        quat_soa=np.broadcast_to(edge.quat_soa[:, :1], (4, n)),
        first_ns=edge.first_ns, last_ns=edge.last_ns,
    )
