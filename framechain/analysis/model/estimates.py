"""Typed estimates of the fault catalogue, and the one text and JSON of each.

Every fault model returns one of these frozen values; the verdict, the evidence sentence, the CLI,
the reports and Rerun all show :func:`format_estimate` of it and nothing else, and
attribution.json stores :func:`estimate_to_json` of it (keys unchanged since schema
framechain/attribution@1).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np


@dataclass(frozen=True)
class LatencyEstimate:
    """The pose (or camera pose) used was ``offset_s`` away from the detection's stamp (signed)."""

    offset_s: float


@dataclass(frozen=True)
class RotationEstimate:
    """The faulty mount relative to the right one: ``angle_deg`` about the unit ``axis`` of ``axis_frame``."""

    angle_deg: float
    axis: tuple[float, float, float]
    axis_frame: str
    faulty: str  # "as run" | "recorded data"


@dataclass(frozen=True)
class TranslationEstimate:
    """The faulty mount's position relative to the right one: ``offset_m`` (x, y, z) in ``frame``'s axes."""

    offset_m: tuple[float, float, float]
    frame: str
    faulty: str  # "as run" | "recorded data"

    @property
    def distance_m(self) -> float:
        return float(np.linalg.norm(self.offset_m))


@dataclass(frozen=True)
class ScaleEstimate:
    """A depth factor (``name="factor"``) or an intrinsics scale (``name="scale"``, variant
    ``"resolution"``: K of another resolution, ``"focal"``: the focal length of another lens)."""

    name: Literal["factor", "scale"]
    value: float
    variant: str | None = None


@dataclass(frozen=True)
class PermutationEstimate:
    """The signed axis permutation the camera-to-body step applied (rows of a 3x3 matrix)."""

    permutation: tuple[tuple[int, int, int], ...]


@dataclass(frozen=True)
class FrameEstimate:
    """The frame looked up, the frame that should have been, and the edges (parent, child) dropped or added."""

    used: str
    meant: str
    hop: str
    skipped: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class InvertedEstimate:
    """A hop (or one recorded edge of it, parent -> child) used the wrong way round."""

    hop: str
    edge: tuple[str, str] | None = None


Estimate = (LatencyEstimate | RotationEstimate | ScaleEstimate | PermutationEstimate | FrameEstimate | InvertedEstimate
            | TranslationEstimate)

_VARIANT_TEXT = {"resolution": "K of another resolution", "focal": "focal length of another lens"}


def format_estimate(estimate: Estimate) -> str:
    """The one human text of an estimate, e.g. ``-31.2 ms`` or ``2.00 deg about -y of camera_link``."""
    match estimate:
        case LatencyEstimate(offset_s=offset_s):
            return f"{offset_s * 1e3:+.1f} ms"
        case RotationEstimate(angle_deg=angle, axis=axis, axis_frame=frame):
            return f"{angle:.2f} deg about {axis_text(axis)}" + (f" of {frame}" if frame else "")
        case ScaleEstimate(value=value, variant=variant):
            text = f"x{value:.4g}"
            if variant:  # no parentheses: the verdict puts this text in parentheses
                text += f", {_VARIANT_TEXT.get(variant, variant)}"
            return text
        case PermutationEstimate(permutation=permutation):
            return f"axes {[list(row) for row in permutation]}"
        case FrameEstimate(used=used, meant=meant, skipped=skipped):
            text = f"looked up {used} instead of {meant}"
            if skipped:  # no parentheses: the verdict puts this text in parentheses
                text += f", skipping {', '.join(f'{p}->{c}' for p, c in skipped)}"
            return text
        case InvertedEstimate(hop=hop, edge=edge):
            return f"{hop} inverted" + (f" at edge {edge[0]}->{edge[1]}" if edge else "")
        case TranslationEstimate(offset_m=offset, frame=frame):
            direction = [float(v) / max(estimate.distance_m, 1e-12) for v in offset]
            return f"{estimate.distance_m * 1e3:.1f} mm along {axis_text(direction)} of {frame}"
    raise TypeError(f"not an estimate: {estimate!r}")


def axis_text(axis: Sequence[float]) -> str:
    """A principal axis by name (``-y``), any other as a rounded vector."""
    a = np.asarray(axis, dtype=float)
    if a.size == 3 and np.max(np.abs(a)) > 0.999:
        k = int(np.argmax(np.abs(a)))
        return f"{'+' if a[k] > 0 else '-'}{'xyz'[k]}"
    return str([round(float(v), 3) + 0.0 for v in a])  # + 0.0 drops negative zeros


def estimate_to_json(estimate: Estimate) -> dict[str, Any]:
    """The attribution.json ``estimate`` object (the keys of schema framechain/attribution@1)."""
    match estimate:
        case LatencyEstimate(offset_s=offset_s):
            return {"offset_s": offset_s}
        case RotationEstimate(angle_deg=angle, axis=axis, axis_frame=frame, faulty=faulty):
            return {"angle_deg": angle, "axis": list(axis), "axis_frame": frame, "faulty": faulty}
        case ScaleEstimate(name=name, value=value, variant=variant):
            out: dict[str, Any] = {name: value}
            if variant is not None:
                out["variant"] = variant
            return out
        case PermutationEstimate(permutation=permutation):
            return {"permutation": [list(row) for row in permutation]}
        case FrameEstimate(used=used, meant=meant, hop=hop, skipped=skipped):
            out = {"used": used, "meant": meant, "hop": hop}
            if skipped:
                out["skipped"] = [list(edge) for edge in skipped]
            return out
        case InvertedEstimate(hop=hop, edge=edge):
            out = {"hop": hop}
            if edge is not None:
                out["edge"] = list(edge)
            return out
        case TranslationEstimate(offset_m=offset, frame=frame, faulty=faulty):
            return {"distance_m": round(estimate.distance_m, 6), "offset_m": [round(v, 6) for v in offset],
                    "frame": frame, "faulty": faulty}
    raise TypeError(f"not an estimate: {estimate!r}")


def estimate_scalars(estimate: Estimate) -> dict[str, float]:
    """The scalar values a bootstrap interval is computed for (offset_s, angle_deg, factor, scale)."""
    match estimate:
        case LatencyEstimate(offset_s=offset_s):
            return {"offset_s": offset_s}
        case RotationEstimate(angle_deg=angle):
            return {"angle_deg": angle}
        case ScaleEstimate(name=name, value=value):
            return {name: value}
        case TranslationEstimate():
            return {"distance_m": estimate.distance_m}
    return {}


def format_interval(interval: Mapping[str, Sequence[float]]) -> str:
    """The 95% intervals of an estimate's scalars in the units of :func:`format_estimate` ("-" for none)."""
    out = []
    for key, (lo, hi) in interval.items():
        if key == "offset_s":
            out.append(f"{lo * 1e3:+.2f} .. {hi * 1e3:+.2f} ms")
        elif key == "angle_deg":
            out.append(f"{lo:.3f} .. {hi:.3f} deg")
        elif key == "distance_m":
            out.append(f"{lo * 1e3:.1f} .. {hi * 1e3:.1f} mm")
        else:
            out.append(f"x{lo:.5g} .. x{hi:.5g}")
    return "; ".join(out) or "-"


__all__ = [
    "Estimate",
    "FrameEstimate",
    "InvertedEstimate",
    "LatencyEstimate",
    "PermutationEstimate",
    "RotationEstimate",
    "ScaleEstimate",
    "TranslationEstimate",
    "axis_text",
    "estimate_scalars",
    "estimate_to_json",
    "format_estimate",
    "format_interval",
]
