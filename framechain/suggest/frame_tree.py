"""What ``framechain info`` shows: the frame tree with per-edge rates and stamp-to-log delays
(the suggested chain and what it needs: :mod:`framechain.suggest.chain`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from framechain.adapters.messages.stamps import CLOCK_GAP_NOTE_S
from framechain.timeline import TransformTable


@dataclass(frozen=True)
class EdgeInfo:
    """One edge of the frame tree, as ``view_frames`` and ``tf2_monitor`` would describe it.

    ``delay_*_s`` are log time minus header stamp over the edge's samples (None for static
    edges, whose stamps are not times of measurement).
    """

    parent: str
    child: str
    is_static: bool
    count: int
    rate_hz: float
    first_stamp_ns: int
    last_stamp_ns: int
    delay_mean_s: float | None
    delay_p95_s: float | None
    delay_max_s: float | None
    sources: tuple[str, ...]
    #: Header stamps and log times are in different clocks (sim time, an unsynchronised sensor).
    clocks_differ: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {
            "parent": self.parent, "child": self.child, "static": self.is_static, "count": self.count,
            "rate_hz": self.rate_hz, "first_stamp_ns": self.first_stamp_ns, "last_stamp_ns": self.last_stamp_ns,
            "span_s": (self.last_stamp_ns - self.first_stamp_ns) * 1e-9, "delay_mean_s": self.delay_mean_s,
            "delay_p95_s": self.delay_p95_s, "delay_max_s": self.delay_max_s, "sources": list(self.sources),
            "clocks_differ": self.clocks_differ,
        }


def frame_tree(transforms: TransformTable) -> list[EdgeInfo]:
    """Every edge (parent, child) with its statistics, sorted by parent then child."""
    if not len(transforms):
        return []
    key = np.char.add(np.char.add(transforms.parent, "\x1f"), transforms.child)
    names, inverse = np.unique(key, return_inverse=True)
    order = np.argsort(inverse, kind="stable")
    bounds = np.searchsorted(inverse[order], np.arange(names.size + 1))
    out: list[EdgeInfo] = []
    for k in range(names.size):
        rows = order[bounds[k] : bounds[k + 1]]
        # From the rows, not the key: a damaged log's frame names may hold the separator.
        parent, child = str(transforms.parent[rows[0]]), str(transforms.child[rows[0]])
        static = bool(transforms.is_static[rows].all())
        stamps = np.sort(transforms.stamp_ns[rows])
        n = int(rows.size)
        span = int(stamps[-1] - stamps[0])
        rate = (n - 1) / (span * 1e-9) if n > 1 and span > 0 and not static else 0.0
        differ = False
        if static:
            mean = p95 = mx = None
        else:
            delay = (transforms.log_time_ns[rows] - transforms.stamp_ns[rows]) * 1e-9
            mean, p95, mx = float(delay.mean()), float(np.percentile(delay, 95)), float(delay.max())
            differ = abs(float(np.median(delay))) > CLOCK_GAP_NOTE_S
        out.append(EdgeInfo(parent, child, static, n, rate, int(stamps[0]), int(stamps[-1]), mean, p95, mx,
                            tuple(sorted(set(transforms.source[rows].tolist()))), differ))
    return out


def tree_roots(edges: list[EdgeInfo]) -> list[str]:
    children = {e.child for e in edges}
    return sorted({e.parent for e in edges} - children)


def children_of(edges: list[EdgeInfo]) -> dict[str, list[EdgeInfo]]:
    out: dict[str, list[EdgeInfo]] = {}
    for e in edges:
        out.setdefault(e.parent, []).append(e)
    return out
