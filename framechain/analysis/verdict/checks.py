"""What a verdict can be checked against: the bounds of each fault family on this log (what it could
see, and the smallest fault it would have found), the error against each family's size, and the
per-label table; with the one text of each that every output shows.

The values are computed by :mod:`~framechain.analysis.verdict.bounds` and :mod:`~framechain.analysis.verdict.curves`;
these are the typed results, their attribution.json form and their words.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

from framechain.analysis.model.estimates import axis_text
from framechain.catalogue import Fault, HopName

#: The estimate key each sized fault family is measured in (``min_detectable`` and the curves use it).
SIZE_KEYS: dict[Fault, str] = {
    Fault.LATENCY: "offset_s",
    Fault.ROTATION_ERROR: "angle_deg",
    Fault.TRANSLATION_ERROR: "distance_m",
    Fault.DEPTH_SCALE: "factor",
    Fault.INTRINSICS: "scale",
}
#: Families measured along a direction (a rotation axis, a translation): a bound is along the weakest one seen.
DIRECTED = (Fault.ROTATION_ERROR, Fault.TRANSLATION_ERROR)
#: What sets a bound: the noise (framechain's statistical thresholds), the tolerance (the smallest effect worth
#: acting on, ``tolerance_m``), whichever asks for the larger fault; or, for a rig camera, what a cross-check of
#: the cameras can pin on one camera (a smaller fault of it is no finding however well it fits).
Limit = Literal["noise", "tolerance", "cross-check"]
LIMIT_WORDS = {"noise": "the noise", "cross-check": "the rig's cross-check"}


def family_name(fault: Fault, hop: HopName) -> str:
    """The family in words: ``pose latency``, ``camera latency``, ``mount rotation``, ``depth scale``."""
    if fault == Fault.LATENCY:
        return "camera latency" if hop == HopName.CAMERA_TO_BODY else "pose latency"
    return {Fault.ROTATION_ERROR: "mount rotation", Fault.TRANSLATION_ERROR: "mount translation",
            Fault.DEPTH_SCALE: "depth scale", Fault.INTRINSICS: "intrinsics scale"}.get(fault,
                                                                                        fault.value.replace("_", " "))


def size_text(fault: Fault, value: float) -> str:
    """A fault size in its display unit: ``4.1 ms``, ``0.3 deg``, ``1.2%`` (a factor's deviation from 1)."""
    if fault == Fault.LATENCY:
        return f"{value * 1e3:.2g} ms" if value < 0.01 else f"{value * 1e3:.0f} ms"
    if fault == Fault.ROTATION_ERROR:
        return f"{value:.2g} deg" if value < 10 else f"{value:.0f} deg"
    if fault == Fault.TRANSLATION_ERROR:
        return f"{value * 1e3:.2g} mm" if value < 0.01 else f"{value * 1e3:.0f} mm"
    return f"{value * 100:.2g}%" if value < 0.1 else f"{value * 100:.0f}%"


@dataclass(frozen=True)
class Bound:
    """What this log's evidence can show of one fault family at one hop.

    ``min_detectable`` is the smallest fault (in the estimate's own key and unit; for a factor or a
    scale its deviation from 1) that framechain's own thresholds would have made a finding worth acting on,
    None when the family is not observable here: the larger of ``statistical`` (the smallest the noise lets
    the fit find) and the smallest that moves the error by the chain's ``tolerance_m``; ``limited_by``
    says which. ``unobservable_axes`` are the rotation axes (or translation directions; unit, in the
    mount's link or parent frame) the evidence cannot see when the others are observable. ``camera``: the
    camera whose chain the bound is of ("" for the chain's one camera).
    """

    hop: HopName
    fault: Fault
    observable: bool
    min_detectable: dict[str, float] | None
    why: str
    unobservable_axes: tuple[tuple[float, float, float], ...] = ()
    #: a rotation's weakest axis seen (unit, in the mount's link frame): ``min_detectable`` is about it
    axis: tuple[float, float, float] | None = None
    camera: str = ""
    #: the smallest fault the noise alone would let the fit find (None: as ``min_detectable``)
    statistical: dict[str, float] | None = None
    limited_by: Limit = "noise"
    #: the tolerance the bound was gated by (m); 0: none
    tolerance_m: float = 0.0

    @property
    def size(self) -> float | None:
        if self.min_detectable is None:
            return None
        return self.min_detectable[SIZE_KEYS[self.fault]]

    @property
    def statistical_size(self) -> float | None:
        """The smallest fault the noise lets the fit find, before the tolerance gates it."""
        if self.statistical is None:
            return self.size
        return self.statistical[SIZE_KEYS[self.fault]]

    @property
    def family(self) -> str:
        """The fault family in words (``camera latency``, ``mount rotation``, ...); a rig camera's stamp
        offset against the other cameras (fitted where its pose is looked up) is its ``latency``."""
        if self.camera and self.fault == Fault.LATENCY and self.hop == HopName.BODY_TO_WORLD:
            return "latency"
        return family_name(self.fault, self.hop)

    def text(self, *, camera: bool = True) -> str:
        """``4.1 ms pose latency`` (observable) or ``pose latency`` (not); ``... on camera X`` for a camera's
        (unless ``camera`` is False: a sentence naming the camera once for several families)."""
        name = self.family + (f" on camera {self.camera}" if self.camera and camera else "")
        if self.size is None:
            return name
        return f"{size_text(self.fault, self.size)} {name}{self.axes_text()}"

    def axes_text(self) -> str:
        """`` (not about [0.25, 0.06, -0.97])`` when some rotation axes (``not along``: translation directions)
        cannot be seen, else empty."""
        if not self.unobservable_axes:
            return ""
        about = "along" if self.fault == Fault.TRANSLATION_ERROR else "about"
        return f" (not {about} {', '.join(axis_text(a) for a in self.unobservable_axes)})"

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"hop": self.hop.value, "fault": self.fault.value,
                               "observable": self.observable,
                               "min_detectable": None if self.min_detectable is None else
                               {k: round(v, 6) for k, v in self.min_detectable.items()},
                               "why": self.why}
        if self.min_detectable is not None:
            out["limited_by"] = self.limited_by
            out["statistical_min_detectable"] = {k: round(v, 6) for k, v in (self.statistical or
                                                                              self.min_detectable).items()}
        if self.camera:
            out["camera"] = self.camera
        if self.axis is not None:
            out["axis"] = list(self.axis)
        if self.unobservable_axes:
            out["unobservable_axes"] = [list(a) for a in self.unobservable_axes]
        return out


def tolerance_text(tolerance_m: float) -> str:
    """``1 mm``, ``0.5 mm``, ``2 cm``: the practical tolerance in words."""
    return f"{tolerance_m * 1e3:g} mm" if tolerance_m < 0.01 else f"{tolerance_m * 1e2:g} cm"


Found = tuple[Fault, HopName] | tuple[Fault, HopName, str | None]


def bounds_sentence(bounds: Sequence[Bound], found: Sequence[Found] = (), *, determined: bool = True) -> str:
    """``No fault above 4 ms pose latency (set by the noise); not observable here: depth scale (...)``.

    Families with a finding (``found``: fault, hop and, for a camera's finding, its camera) are left
    out; with findings the sentence says "no other fault". Each size says what sets it: the noise, or the
    chain's tolerance (a smaller fault would be clear but not worth acting on). ``determined`` False (an
    inconclusive verdict): the sizes are what the log could show, never "no fault". Empty when there are no
    bounds.
    """
    families_found = {(bound_family(f[0]), f[1], (f[2] if len(f) > 2 else "") or "") for f in found}
    rest = [b for b in bounds if (bound_family(b.fault), b.hop, b.camera) not in families_found]
    # A camera's families are named together, the camera once.
    by_camera: dict[str, list[Bound]] = {}
    for b in rest:
        if b.observable:
            by_camera.setdefault(b.camera, []).append(b)
    seen = [f"{_limited(mine)} on camera {camera}" if camera else _limited(mine) for camera, mine in by_camera.items()]
    # Families not observable for one cause are named together, with the cause (the why up to its colon, after the
    # camera a camera's why starts with: the camera is named once already).
    causes: dict[tuple[str, str], list[str]] = {}
    for b in rest:
        if not b.observable:
            why = b.why.removeprefix(f"camera {b.camera}: ") if b.camera else b.why
            causes.setdefault((why.split(":")[0].rstrip("."), b.camera), []).append(b.text(camera=False))
    blind = [f"{_and(names)}{f' on camera {camera}' if camera else ''} ({cause})"
             for (cause, camera), names in causes.items()]
    parts = []
    if seen:
        lead = (f"No {'other ' if found else ''}fault above " if determined else
                "The smallest faults this log would show: ")
        parts.append(lead + "; ".join(seen))
    if blind:
        parts.append(f"not observable here: {'; '.join(blind)}")
    if not parts:
        return ""
    text = "; ".join(parts)
    return text[0].upper() + text[1:] + "."


def _limited(bounds: Sequence[Bound]) -> str:
    """``4 ms pose latency and 0.3 deg mount rotation (set by the noise), 2 mm mount translation (set by the 1 mm
    tolerance)``: sizes grouped by what sets them, in the order given."""
    groups: dict[str, list[str]] = {}
    for b in bounds:
        limit = LIMIT_WORDS.get(b.limited_by, f"the {tolerance_text(b.tolerance_m)} tolerance")
        groups.setdefault(limit, []).append(b.text(camera=False))
    return ", ".join(f"{_and(names)} (set by {limit})" for limit, names in groups.items())


def _and(names: Sequence[str]) -> str:
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def bound_family(fault: Fault) -> Fault:
    """A rotation finding (missing or wrong) is of the mount-rotation family."""
    return Fault.ROTATION_ERROR if fault == Fault.MISSING_ROTATION else fault


@dataclass(frozen=True)
class Undetermined:
    """A fit whose estimate cannot be trusted, and why: at the edge of its search window, an interval spanning
    orders of magnitude, a misfit the corrections do not explain. A verdict that rests on one is inconclusive."""

    what: str  # "latency at body_to_world (+998.0 ms)", "the error left by the findings"
    why: str
    camera: str = ""

    def text(self) -> str:
        on = f" on camera {self.camera}" if self.camera else ""
        return f"{self.what}{on} is undetermined ({self.why})"

    def to_json(self) -> dict[str, Any]:
        return {"what": self.what, "why": self.why, **({"camera": self.camera} if self.camera else {})}


def inconclusive_sentence(undetermined: Sequence[Undetermined], measured: str, bounds: str = "") -> str:
    """``Inconclusive: <what> is undetermined (<why>); ... . <measured> <bounds>`` (never "no fault": the fits
    that would decide cannot be trusted; ``bounds`` is worded with ``determined=False``)."""
    items = "; ".join(u.text() for u in undetermined)
    text = f"Inconclusive: {items}."
    if measured:
        text += f" {measured[0].upper()}{measured[1:]}"
    return text + (f" {bounds}" if bounds else "")


def nothing_observable(bounds: Sequence[Bound]) -> bool:
    """Whether no fault family could be checked on this log (no bounds at all counts as none)."""
    return not any(b.observable for b in bounds)


@dataclass(frozen=True)
class Curve:
    """The error against the evidence as one fault family's size is varied (the other findings applied).

    ``x`` is in the estimate's key (``offset_s``; ``angle_deg`` signed about ``axis``; the ``factor``
    or ``scale`` itself); ``median_error_m`` is what the findings' millimetres are shares of and
    ``rms_error_m`` what the fit minimises (its dip is the estimate; the median's bottom is flatter);
    ``estimate`` is the finding's value (None: not found) and ``bound`` the family's
    ``min_detectable`` (a deviation from 1 for a factor or scale).
    """

    hop: HopName
    fault: Fault
    key: str
    x: tuple[float, ...]
    median_error_m: tuple[float, ...]
    rms_error_m: tuple[float, ...]
    estimate: float | None = None
    bound: float | None = None
    axis: tuple[float, float, float] | None = None

    @property
    def no_fault(self) -> float:
        return 1.0 if self.key in ("factor", "scale") else 0.0

    def axis_label(self) -> str:
        return {
            "offset_s": "time offset of the pose (ms)" if self.hop == HopName.BODY_TO_WORLD
            else "time offset of the camera pose (ms)",
            "angle_deg": f"mount rotation about {axis_text(self.axis or (0.0, 0.0, 1.0))} (deg)",
            "distance_m": f"mount position moved along {axis_text(self.axis or (0.0, 0.0, 1.0))} (mm)",
            "factor": "depth factor", "scale": "intrinsics scale",
        }[self.key]

    def bound_edges(self) -> tuple[float, float] | None:
        """Where the bound lies either side of the estimate (a family found: a further fault) or of no fault."""
        if self.bound is None:
            return None
        centre = self.no_fault if self.estimate is None else self.estimate
        if self.key in ("factor", "scale"):
            return centre * (1.0 - self.bound), centre * (1.0 + self.bound)
        return centre - self.bound, centre + self.bound

    def display(self, value: float) -> float:
        """A value of ``x`` in the plot's unit (ms for offsets)."""
        return value * 1e3 if self.key in ("offset_s", "distance_m") else value

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "hop": self.hop.value, "fault": self.fault.value, "key": self.key,
            "x": [round(v, 7) for v in self.x], "median_error_m": [round(v, 7) for v in self.median_error_m],
            "rms_error_m": [round(v, 7) for v in self.rms_error_m], "estimate": self.estimate, "bound": self.bound,
        }
        if self.axis is not None:
            out["axis"] = list(self.axis)
        return out


#: "wrong size": its spread grows with its distance from the camera, as a tag declared at the wrong size does
LabelVerdict = Literal["static", "moving", "outlier", "too few", "agrees", "wrong size"]


@dataclass(frozen=True)
class LabelRow:
    """One label (tag id, class) of the evidence: how often it was seen and used, its spread (the
    median distance of its points from its own object's position, or from the evidence), a verdict."""

    label: str
    observations: int
    used: int
    spread_m: float | None
    p90_m: float | None
    verdict: LabelVerdict
    #: a "wrong size" label's size that fits (m), and the one declared
    size_m: float | None = None
    declared_m: float | None = None

    def to_json(self) -> dict[str, Any]:
        out = {"label": self.label, "observations": self.observations, "used": self.used,
               "spread_m": None if self.spread_m is None else round(self.spread_m, 6),
               "p90_m": None if self.p90_m is None else round(self.p90_m, 6), "verdict": self.verdict}
        if self.size_m is not None:
            out.update(size_m=self.size_m, declared_m=self.declared_m)
        return out


@dataclass(frozen=True)
class LabelTable:
    """The per-label table and the labels framechain would suggest ignoring (moving or outliers)."""

    rows: tuple[LabelRow, ...] = ()
    overall_m: float | None = None  # the median spread over every used observation
    #: the sizes the chain declares (``evidence.tag_size_m``), to write the corrected ones beside
    declared: float | dict[str, float] | None = None

    @property
    def suggest_ignore(self) -> tuple[str, ...]:
        return tuple(r.label for r in self.rows if r.verdict in ("moving", "outlier"))

    @property
    def wrongly_sized(self) -> tuple[LabelRow, ...]:
        return tuple(r for r in self.rows if r.verdict == "wrong size")

    def size_line(self) -> str | None:
        """``evidence.tag_size_m: {default: 0.16, 100: 0.1}``: the declared sizes with the wrong ones corrected
        (None: none is wrong)."""
        wrong = self.wrongly_sized
        if not wrong:
            return None
        declared = self.declared
        sizes = {"default": float(declared)} if isinstance(declared, float | int) else dict(declared or {})
        sizes.update({r.label: r.size_m for r in wrong if r.size_m is not None})
        return "evidence.tag_size_m: {" + ", ".join(f"{k}: {v:g}" for k, v in sizes.items()) + "}"

    def ignore_line(self) -> str | None:
        """``evidence.ignore_labels: [3, 7]`` ready to paste (None: nothing to ignore)."""
        labels = self.suggest_ignore
        if not labels:
            return None
        items = ", ".join(label if label.lstrip("-").isdigit() else repr(label) for label in labels)
        return f"evidence.ignore_labels: [{items}]"

    def to_json(self) -> dict[str, Any]:
        return {"rows": [r.to_json() for r in self.rows],
                "overall_m": None if self.overall_m is None else round(self.overall_m, 6),
                "suggest_ignore": list(self.suggest_ignore), "ignore_line": self.ignore_line(),
                "wrongly_sized": [r.label for r in self.wrongly_sized], "size_line": self.size_line()}


__all__ = [
    "DIRECTED",
    "SIZE_KEYS",
    "Bound",
    "Curve",
    "LabelRow",
    "LabelTable",
    "LabelVerdict",
    "Limit",
    "Undetermined",
    "bound_family",
    "bounds_sentence",
    "family_name",
    "inconclusive_sentence",
    "nothing_observable",
    "size_text",
    "tolerance_text",
]
