"""Labels whose size is wrong: a tag declared at k times its true size puts every depth from its corners k times too
far along its ray, so the static tag, seen from different distances, spreads along the rays in proportion to its
distance from the camera, as if it moved. Scaling each of its points towards its camera by one factor ``s`` (its
true size over the declared one) brings them back onto one point; a tag that moves is not helped.

Per label, over its static objects (label and window), the points ``p_i`` seen from camera centres ``c_i`` give
``v_i = p_i - c_i``; ``c_i + s v_i`` should be one point per object. Least squares in ``s`` and the objects' points
is linear: with the object means removed, ``s = -sum (c_i - c_bar) . (v_i - v_bar) / sum |v_i - v_bar|^2`` over
every object of the label (bincounts, no loop over observations).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from framechain.analysis.evidence.static import StaticGroups
from framechain.analysis.model.chain import ChainInputs, Perturbation, hop1, hop2, hop3
from framechain.arrays import FloatArray, IntArray, StrArray

#: A label's size is called wrong when one factor takes its spread to at most this share of what it was, and the
#: factor is at least this far from 1 (a few percent is the printing, or the depth noise).
SIZE_SPREAD_SHARE = 0.5
SIZE_MIN_OFF = 0.05


@dataclass(frozen=True)
class SizeFit:
    """One label: the factor its size is off by (true over declared), its spread before and after it (m)."""

    factor: float
    spread_m: float
    spread_sized_m: float
    declared_m: float

    @property
    def size_m(self) -> float:
        """The size that fits, rounded to a tenth of a millimetre."""
        return round(self.declared_m * self.factor, 4)

    @property
    def wrong(self) -> bool:
        return abs(self.factor - 1.0) >= SIZE_MIN_OFF and self.spread_sized_m <= SIZE_SPREAD_SHARE * self.spread_m


def declared_size(sizes: float | Mapping[str, float] | None, label: str) -> float | None:
    """The size the chain declares for a label's tag (its own, else the default; None: none)."""
    if sizes is None or isinstance(sizes, float | int):
        return None if sizes is None else float(sizes)
    own = sizes.get(label, sizes.get("default"))
    return None if own is None else float(own)


def label_size_fits(inputs: ChainInputs, pert: Perturbation, groups: StaticGroups, labels: StrArray,
                    sizes: float | Mapping[str, float] | None) -> dict[str, SizeFit]:
    """Per label with a declared size: the factor its points' distances from the camera are off by, and its spread
    (median distance from its objects' means) before and after (``labels``: the observations', rows of ``inputs``)."""
    n = len(inputs)
    zeros = np.zeros((n, 3))
    centre, ok = hop3(inputs, pert, hop2(inputs, pert, zeros))
    point, ok_point = hop3(inputs, pert, hop2(inputs, pert, hop1(inputs, pert)))
    used = groups.used & ok & ok_point & np.isfinite(point).all(axis=1) & np.isfinite(centre).all(axis=1)
    if not used.any():
        return {}
    g = np.where(used, groups.group, 0)
    n_groups = max(groups.n_groups, 1)
    weight = used.astype(float)
    count = np.maximum(np.bincount(g, weight, minlength=n_groups), 1.0)
    ray = point - centre
    c_dev = centre - _means(centre, g, weight, count)[g]
    v_dev = ray - _means(ray, g, weight, count)[g]
    names, code = np.unique(np.asarray(labels, dtype=str), return_inverse=True)
    code = np.where(used, code, 0)
    cross = np.bincount(code, weight * np.einsum("ij,ij->i", c_dev, v_dev), minlength=names.size)
    power = np.bincount(code, weight * np.einsum("ij,ij->i", v_dev, v_dev), minlength=names.size)
    factor = np.divide(-cross, power, out=np.ones(names.size), where=power > 1e-12)
    before = np.linalg.norm(c_dev + v_dev, axis=1)
    after = np.linalg.norm(c_dev + factor[code][:, None] * v_dev, axis=1)
    out = {}
    for k, name in enumerate(names.tolist()):  # one entry per label (tens), not per observation
        mine = used & (code == k)
        declared = declared_size(sizes, name)
        if declared is None or mine.sum() < 3 or not np.isfinite(factor[k]) or factor[k] <= 0:
            continue
        out[name] = SizeFit(float(factor[k]), float(np.median(before[mine])), float(np.median(after[mine])),
                            declared)
    return out


def _means(values: FloatArray, group: IntArray, weight: FloatArray, count: FloatArray) -> FloatArray:
    out: FloatArray = np.stack([np.bincount(group, weight * values[:, k], minlength=count.size)
                                for k in range(3)], axis=1) / count[:, None]
    return out


__all__ = ["SIZE_MIN_OFF", "SIZE_SPREAD_SHARE", "SizeFit", "declared_size", "label_size_fits"]
