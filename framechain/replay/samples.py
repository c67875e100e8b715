"""What a TransformBuffer hands out: the graph's edges and paths, the samples each hop used, and
the lookup result with a status per time (see :mod:`framechain.replay.buffer` for the semantics)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Final

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray, IntArray
from framechain.geometry.rotations import IDENTITY, quat_rotate, quat_to_matrix
from framechain.replay.errors import ConnectivityError, ExtrapolationError


class _Latest:
    """Sentinel type of :data:`LATEST`."""

    _instance: _Latest | None = None

    def __new__(cls) -> _Latest:
        if cls._instance is None:
            cls._instance = super().__new__(cls)
        return cls._instance

    def __repr__(self) -> str:
        return "LATEST"


#: The latest time common to every dynamic edge of a path (tf2's ``time 0``); explicit, not 0.
LATEST: Final = _Latest()

TimesLike = npt.ArrayLike | _Latest


class LookupStatus(IntEnum):
    """Per-time outcome of a lookup, ordered by severity (the worst hop wins)."""

    OK = 0
    NEAREST = 1  # outside the span but within the tolerance: the nearest sample was used
    EXTRAPOLATED_PAST = 2
    EXTRAPOLATED_FUTURE = 3
    NO_PATH = 4


@dataclass(frozen=True)
class Edge:
    """The samples of one edge ``T_parent_child``, sorted by header stamp (duplicates dropped)."""

    parent: str
    child: str
    is_static: bool
    stamps_ns: IntArray
    translation: FloatArray
    quat_xyzw: FloatArray
    source: str
    #: rotation vectors (3, n-1) of ``R_i^-1 R_(i+1)``: slerp becomes one exp per query.
    delta_rotvec: FloatArray = field(repr=False)
    #: components-first copies (3, n) and (4, n) for the vectorised hot path.
    translation_soa: FloatArray = field(repr=False)
    quat_soa: FloatArray = field(repr=False)

    @property
    def first_ns(self) -> int:
        return int(self.stamps_ns[0])

    @property
    def last_ns(self) -> int:
        return int(self.stamps_ns[-1])


@dataclass(frozen=True)
class PathHop:
    """One edge on a path; ``inverse`` when the walk goes from parent to child."""

    parent: str
    child: str
    inverse: bool
    is_static: bool


@dataclass(frozen=True)
class FramePath:
    """The edges joining ``source`` to ``target`` through their nearest common ancestor."""

    target: str
    source: str
    hops: tuple[PathHop, ...]
    #: Why there is no path (unknown frame, disconnected trees); empty when there is one.
    problem: str = ""

    @property
    def connected(self) -> bool:
        return not self.problem

    @property
    def frames(self) -> tuple[str, ...]:
        """Frame names from source to target."""
        names = [self.source]
        for hop in self.hops:
            names.append(hop.child if hop.inverse else hop.parent)
        return tuple(names)


@dataclass(frozen=True)
class HopSamples:
    """What one hop of a path used at every query time."""

    hop: PathHop
    times_ns: IntArray
    stamp_before_ns: IntArray  # stamp of the older sample used (static: the static sample's)
    stamp_after_ns: IntArray  # stamp of the newer sample used (== before for an exact hit)
    weight: FloatArray  # interpolation ratio in [0, 1]
    status: npt.NDArray[np.uint8]
    translation_soa: FloatArray  # (3, N) T_parent_child at each time (NaN where not usable)
    quat_soa: FloatArray  # (4, N)
    first_ns: int
    last_ns: int

    @property
    def translation(self) -> FloatArray:
        """(N, 3) translation of ``T_parent_child`` used at each time."""
        return self.translation_soa.T

    @property
    def quat_xyzw(self) -> FloatArray:
        """(N, 4) rotation of ``T_parent_child`` used at each time."""
        return self.quat_soa.T

    @property
    def gap_ns(self) -> IntArray:
        """Query time minus the stamp of the nearest sample used (0 for static edges)."""
        if self.hop.is_static:
            return np.zeros_like(self.times_ns)
        near = np.where(
            np.abs(self.times_ns - self.stamp_before_ns) <= np.abs(self.stamp_after_ns - self.times_ns),
            self.stamp_before_ns,
            self.stamp_after_ns,
        )
        return self.times_ns - near


@dataclass(frozen=True)
class LookupResult:
    """``T_target_source`` at N times, with the per-hop samples and a status per time."""

    target: str
    source: str
    times_ns: IntArray
    translation: FloatArray  # (N, 3), NaN where status is not usable
    quat_xyzw: FloatArray  # (N, 4), NaN where status is not usable
    status: npt.NDArray[np.uint8]
    hops: tuple[HopSamples, ...]
    path: FramePath

    def __len__(self) -> int:
        return int(self.times_ns.shape[0])

    @property
    def ok(self) -> npt.NDArray[np.bool_]:
        """Times whose transform is usable (exact, interpolated, or nearest within tolerance)."""
        return self.status <= LookupStatus.NEAREST

    def matrix(self) -> FloatArray:
        """Homogeneous matrices (N, 4, 4); NaN where the lookup failed."""
        q = np.where(self.ok[:, None], self.quat_xyzw, IDENTITY)
        out = np.tile(np.eye(4), (len(self), 1, 1))
        out[:, :3, :3] = quat_to_matrix(q.T)
        out[:, :3, 3] = self.translation
        out[~self.ok, :3, :] = np.nan
        return out

    def apply(self, points: npt.ArrayLike) -> FloatArray:
        """Map points (N, 3) given in ``source`` into ``target``; NaN where the lookup failed."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        return (quat_rotate(self.quat_xyzw.T, p.T) + self.translation.T).T

    def raise_for_status(self) -> None:
        """Raise the tf2-like exception of the first failing time, if any."""
        if not self.path.connected:
            raise ConnectivityError(self.path.problem)
        bad = np.flatnonzero(~self.ok)
        if bad.size == 0:
            return
        i = int(bad[0])
        for hop in self.hops:
            if hop.status[i] > LookupStatus.NEAREST:
                raise ExtrapolationError(
                    hop.hop.parent, hop.hop.child, int(hop.times_ns[i]), hop.first_ns, hop.last_ns
                )
