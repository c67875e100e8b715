"""What attribution returns: the findings, the Attribution with its summaries and the attribution.json
contract, and the error raised (with its typed reason) when a log cannot be attributed."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import Any, Literal

import numpy as np

from framechain.analysis.evidence.alignment import AlignedEvidence
from framechain.analysis.evidence.rig_layout import RigLayout
from framechain.analysis.model.chain import ChainInputs
from framechain.analysis.model.estimates import Estimate, estimate_to_json, format_estimate
from framechain.analysis.verdict.checks import (
    Bound,
    Curve,
    LabelTable,
    Undetermined,
    bounds_sentence,
    inconclusive_sentence,
    nothing_observable,
    tolerance_text,
)
from framechain.arrays import FloatArray
from framechain.catalogue import Fault, HopName
from framechain.config.chain import ChainConfig
from framechain.errors import FramechainError
from framechain.replay import REPLAYED, ReplayResult

Metric = Literal["logged_hops", "target", "reference", "static_spread", "camera_motion", "cross_camera", "none"]
#: What the error is measured against, as the verdict says it.
METRIC_WORDS = {"static_spread": "static spread", "cross_camera": "other cameras of the rig"}
SCHEMA = "framechain/attribution@1"


class Unattributed(StrEnum):
    """Why a run has no attribution."""

    NOT_ASKED = "not_asked"  # the run was asked to replay only (--no-attribute)
    NO_DETECTIONS = "no_detections"  # nothing to replay
    NOTHING_REPLAYED = "nothing_replayed"  # every observation was rejected
    NO_CAMERA_INFO = "no_camera_info"  # no camera model for the replayed observations
    STATIC_TARGET = "static_target"  # observations replayed, but too few sightings of one static object


class AnalysisError(FramechainError):
    """The log could not be analysed (nothing replayed, no camera model, too few sightings)."""

    def __init__(self, message: str, reason: Unattributed = Unattributed.NOTHING_REPLAYED) -> None:
        super().__init__(message)
        self.reason = reason


@dataclass(frozen=True)
class Finding:
    """One fault found: the catalogue entry, its size, its share of the error and the fix."""

    fault: Fault
    hop: HopName
    estimate: Estimate
    interval: dict[str, list[float]]
    share: float
    error_m: float
    confidence: float
    evidence: str
    fix: str
    model: str
    #: "weak" when its 95% interval holds "no fault", its confidence is low or it is under the bound of
    #: its family (``weak_because`` says which): the fix is then a hint to check, not a change to make;
    #: "note" when its effect is under the practical threshold (no action needed, however certain the fit);
    #: "undetermined" when its fit cannot be trusted (``undetermined_because``): no fix, and the verdict is
    #: inconclusive. Strength words follow the effect and the fit, not the BIC alone.
    strength: Literal["strong", "weak", "note", "undetermined"] = "strong"
    weak_because: tuple[str, ...] = ()
    #: The camera the finding is about (its frame as in the chain); None: the chain's one camera.
    camera: str | None = None
    #: The unit of ``error_m``: metres, or deg/s for a camera's rotation rate (evidence from its own motion).
    error_unit: str = "m"
    #: Why its fit cannot be trusted (at the edge of its search window, an interval over orders of magnitude).
    undetermined_because: tuple[str, ...] = ()
    #: A rig camera's finding: the error it removes from that camera's own observations (a share of the whole rig's
    #: median undersells a fault of one camera among many); None: the finding's effect is ``error_m``.
    own_effect_m: float | None = None

    @property
    def actionable(self) -> bool:
        """A fix to make: its effect passes the practical threshold and its fit can be trusted (not a "note",
        "statistically clear, 0.2 mm: no action needed", nor an undetermined fit)."""
        return self.strength in ("strong", "weak")

    @property
    def effect_m(self) -> float:
        """The error it removes, in ``error_m``'s unit: what the practical threshold gates."""
        return self.error_m if self.own_effect_m is None else self.own_effect_m

    @property
    def effect(self) -> float:
        """The error it removes in its display unit: millimetres, or deg/s of a camera's rotation rate."""
        return self.effect_m * 1e3 if self.error_unit == "m" else self.effect_m

    @property
    def effect_unit(self) -> str:
        return "mm" if self.error_unit == "m" else self.error_unit

    def effect_text(self) -> str:
        """``0.2 mm``, ``1355.4 mm``, ``3.10 deg/s``."""
        return f"{self.effect:.1f} mm" if self.error_unit == "m" else f"{self.effect:.2f} {self.error_unit}"

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "fault": self.fault.value,
            "hop": self.hop.value,
            **({} if self.camera is None else {"camera": self.camera}),
            "estimate": estimate_to_json(self.estimate),
            "interval": self.interval,
            "share": round(self.share, 4),
            "error_m": round(self.error_m, 6) if self.error_unit == "m" else None,
            "confidence": round(self.confidence, 4),
            "evidence": self.evidence,
            "fix": self.fix,
            "strength": self.strength,
            "weak_because": list(self.weak_because),
            "effect": {"value": round(self.effect, 4), "unit": self.effect_unit,
                       **({"on": f"camera {self.camera}'s observations"} if self.own_effect_m is not None else {})},
            "actionable": self.actionable,
        }
        if self.undetermined_because:
            out["undetermined_because"] = list(self.undetermined_because)
        if self.error_unit != "m":
            out["error_deg_s"] = round(self.error_m, 6)
        return out


def _beside_hop(finding: Finding) -> str:
    """The estimate's text and a comma, unless it only says the hop again (``camera_to_body inverted``)."""
    text = format_estimate(finding.estimate)
    return "" if text == f"{finding.hop.value} inverted" else f"{text}, "


def as_note(finding: Finding, threshold: float, threshold_text: str) -> Finding:
    """The finding as a note: its effect is under the practical ``threshold`` (in ``error_m``'s unit; its words
    ``threshold_text``, e.g. ``the 1 mm tolerance (tolerance_m)``), so no fix is offered, however certain its fit."""
    clear = ("statistically clear" if finding.strength == "strong" else
             f"weak ({'; '.join(finding.weak_because)})")
    return replace(finding, strength="note",
                   fix=f"{clear}, {finding.effect_text()}: no action needed, under {threshold_text}.")


def as_undetermined(finding: Finding, why: Sequence[str]) -> Finding:
    """The finding as an undetermined fit: no fix, and the verdict that rests on it is inconclusive."""
    return replace(finding, strength="undetermined", undetermined_because=tuple(why),
                   fix=f"undetermined ({'; '.join(why)}): no fix from this fit; get evidence that pins it down "
                       "before changing anything.")


def gate_by_effect(findings: Sequence[Finding], threshold: float, threshold_text: str) -> tuple[Finding, ...]:
    """The findings whose effect (``error_m``) is under ``threshold`` made notes (:func:`as_note`); the others,
    and the undetermined, as they are."""
    return tuple(as_note(f, threshold, threshold_text) if f.strength in ("strong", "weak") and f.effect_m < threshold
                 else f for f in findings)


@dataclass(frozen=True)
class Attribution:
    """The result of :func:`attribute`: counts, error, findings, and what they were computed from."""

    source: dict[str, Any]
    config: ChainConfig
    replay: ReplayResult
    inputs: ChainInputs
    metric: Metric
    error_before: FloatArray  # (N,) per replayed observation, against the evidence
    error_after: FloatArray  # (N,) once every finding is corrected
    hop_errors: dict[str, FloatArray]  # hop -> (N,) departure of the logged hop (logged-hops level)
    evidence_points: FloatArray  # (N, 3) world-frame evidence per replayed observation (NaN: none)
    corrected_world: FloatArray  # (N, 3) world points with the findings applied
    findings: tuple[Finding, ...]
    seed: int
    #: the logged evidence aligned to every observation of ``replay`` (all rows, in the chain's frames)
    aligned: AlignedEvidence
    notes: tuple[str, ...] = ()
    #: where the error is measured: the world point, or the deepest hop the robot logged
    stage: str = "world"
    #: per fault family and hop: whether this log could show it and the smallest fault it would have found
    bounds: tuple[Bound, ...] = ()
    #: the error against each fitted family's size (latency: the time offsets searched)
    curves: tuple[Curve, ...] = ()
    #: per label: observations, spread and verdict (static, moving, outlier), and the labels to ignore
    labels: LabelTable = field(default_factory=LabelTable)
    #: What each camera's own motion says (time offset, mount, link, observability), one JSON entry per
    #: camera: the findings of a run measured against it (metric camera_motion), else corroboration.
    camera_motion: tuple[dict[str, Any], ...] = ()
    #: Metric camera_motion: the rotation-rate residual per frame pair (deg/s), before and after the findings.
    rate_residual: tuple[FloatArray, FloatArray] | None = None
    #: a rig's cameras: which are compared with which, the gauges, what cannot be seen (None: one camera)
    rig: RigLayout | None = None
    #: The fits the verdict would rest on that cannot be trusted: with any, the verdict is "Inconclusive: ..."
    #: and never says "no fault" (a camera's own motion fills it for its fits as a chain fit does for its own).
    undetermined: tuple[Undetermined, ...] = ()
    #: Per finding (in the order of ``findings``): how far the other findings' faults together move each world
    #: point, (N, 3), every fault applied minus this one alone. An as-run point less it shows this finding's
    #: own effect; empty where findings do not come from a chain fit (a camera's own motion).
    others_shift: tuple[FloatArray, ...] = ()

    @property
    def nothing_checked(self) -> bool:
        """No evidence measured the chain: none in the log, or only cameras whose own motion shows nothing (an arm
        that does not turn, an episode too short), with no finding and nothing undetermined."""
        if self.metric == "none":
            return True
        return self.metric == "camera_motion" and not (any_observable(self.camera_motion) or self.findings
                                                       or self.undetermined)

    def counts(self) -> dict[str, Any]:
        return self.replay.counts()

    def error_summary(self, errors: FloatArray | None = None) -> dict[str, Any]:
        """Median, p95 and max of the error (metres; deg/s of camera rotation rate for metric camera_motion,
        where ``error_before`` / ``error_after`` stand for the rate residual before and after the findings)."""
        e = self.error_before if errors is None else errors
        unit: dict[str, str] = {}
        if self.metric == "camera_motion" and self.rate_residual is not None:
            e = self.rate_residual[1] if errors is self.error_after else self.rate_residual[0]
            unit = {"unit": "deg/s"}
        e = e[np.isfinite(e)]
        if e.size == 0:
            return {"metric": self.metric, "stage": self.stage, **unit, "median": None, "p95": None, "max": None}
        return {
            "metric": self.metric,
            "stage": self.stage,
            **unit,
            "median": round(float(np.median(e)), 6),
            "p95": round(float(np.percentile(e, 95)), 6),
            "max": round(float(e.max()), 6),
        }

    def hop_summary(self) -> list[dict[str, Any]]:
        """One row per hop: its own departure where the robot logged it, the time gaps of the samples
        it used (observation stamp minus the nearest sample of its stalest edge), stale count, and
        the error the findings put on it."""
        records = self.replay.hops
        replayed = records.status == REPLAYED
        rows = []
        for hop in HopName:
            sel = replayed & (records.hop == hop.value)
            gaps_ms = np.abs(records.gap_ns[sel]) * 1e-6
            departure = self.hop_errors.get(hop.value)
            dep = departure[np.isfinite(departure)] if departure is not None else np.zeros(0)
            rows.append({
                "hop": hop.value,
                "departure_m": None if dep.size == 0 else {
                    "median": round(float(np.median(dep)), 6), "p95": round(float(np.percentile(dep, 95)), 6),
                    "max": round(float(dep.max()), 6)},
                "gap_ms": None if gaps_ms.size == 0 else {
                    "median": round(float(np.median(gaps_ms)), 3), "max": round(float(gaps_ms.max()), 3)},
                "stale": int(records.stale[sel].sum()),
                "attributed_m": round(sum(f.error_m for f in self.findings if f.hop == hop and f.error_unit == "m"), 6),
                "faults": [f.fault.value for f in self.findings if f.hop == hop],
            })
        return rows

    @property
    def verdict(self) -> str:
        """The answer in one sentence: the findings first, then the bounds of the families not found and
        what this log cannot show."""
        summary = self.error_summary()
        if self.metric == "none":
            return ("No evidence in this log to measure the chain against (no logged points, reference or static "
                    "target): nothing could be checked.")
        if self.metric == "camera_motion":  # its own "Inconclusive: ..." for the undetermined, camera by camera
            return self._motion_verdict(summary)
        if self.undetermined:
            return self._inconclusive(summary)
        bounds = self._bounds_sentence()
        unseen = self._rig_unobservable()
        against = (f"median error {summary['median'] * 1e3:.1f} mm against the "
                   f"{METRIC_WORDS.get(self.metric, self.metric.replace('_', ' '))}")
        actionable = [f for f in self.findings if f.actionable]
        if not actionable:
            if self.bounds and nothing_observable(self.bounds) and not self.findings:
                return f"Nothing could be checked ({against}{unseen}): {bounds[0].lower()}{bounds[1:]}"
            lead = "No fault worth acting on" if self.findings else "No fault beyond noise"
            return (f"{lead}: {against}{unseen}{self._notes_clause()}{self._sizes_clause()}." +
                    (f" {bounds}" if bounds else ""))
        top = actionable[0]
        more = f", plus {len(actionable) - 1} more" if len(actionable) > 1 else ""
        camera = f" on camera {top.camera}" if top.camera else ""
        weak = f" (weak: {'; '.join(top.weak_because)})" if top.strength == "weak" else ""
        found = (f"{top.fault.value} at {top.hop.value}{camera} ({format_estimate(top.estimate)}){weak} explains "
                 f"{top.share:.0%} of a median {summary['median'] * 1e3:.1f} mm error{more}{unseen}"
                 f"{self._notes_clause()}{self._sizes_clause()}.")
        return found + (f" {bounds}" if bounds else "")

    def _notes_clause(self) -> str:
        """``; depth_scale at pixel_to_camera (x0.98, 0.2 mm) is statistically clear but under the 1 mm tolerance:
        no action needed`` for the findings that are notes ("" without)."""
        notes = [f for f in self.findings if f.strength == "note"]
        if not notes:
            return ""
        named = [f"{f.fault.value} at {f.hop.value}{f' on camera {f.camera}' if f.camera else ''} "
                 f"({_beside_hop(f)}{f.effect_text()})" for f in notes]
        listed = named[0] if len(named) == 1 else f"{', '.join(named[:-1])} and {named[-1]}"
        verb = "is" if len(named) == 1 else "are"
        return (f"; {listed} {verb} clear but under the {tolerance_text(self.config.tolerance_m)} tolerance: "
                "no action needed")

    def _sizes_clause(self) -> str:
        """``; labels 100, 101 look wrongly sized, not moving (the label table gives their sizes)`` ("" without)."""
        wrong = [r.label for r in self.labels.wrongly_sized]
        if not wrong:
            return ""
        return (f"; label{'s' if len(wrong) > 1 else ''} {', '.join(wrong)} look{'' if len(wrong) > 1 else 's'} "
                "wrongly sized, not moving (the label table gives the sizes that fit)")

    def _inconclusive(self, summary: dict[str, Any]) -> str:
        """The verdict when the fits that would decide cannot be trusted: what is undetermined and why, what was
        measured, and what the log could show once they are; never "no fault"."""
        if summary["median"] is None:
            measured = ""
        elif self.metric == "camera_motion":
            measured = (f"median rotation-rate misfit {summary['median']:.2f} deg/s against forward kinematics; "
                        "nothing is concluded from it.")
        else:
            words = METRIC_WORDS.get(self.metric, self.metric.replace("_", " "))
            measured = f"median error {summary['median'] * 1e3:.1f} mm against the {words}"
            determined = [f for f in self.findings if f.actionable]
            if determined:
                top = determined[0]
                measured += (f"; of the fits that hold, {top.fault.value} at {top.hop.value} "
                             f"({format_estimate(top.estimate)}) explains {top.share:.0%} of it")
            measured += f"{self._rig_unobservable()}."
        found = [(f.fault, f.hop, f.camera or "") for f in self.findings]
        return inconclusive_sentence(self.undetermined, measured,
                                     bounds_sentence(self.bounds, found, determined=False) if self.bounds else "")

    def _bounds_sentence(self) -> str:
        """The bounds of the families not found, or what was not bounded when nothing measured them."""
        if not self.bounds:
            words = METRIC_WORDS.get(self.metric, self.metric.replace("_", " "))
            return (f"Not bounded: the smallest fault this log would have shown was not computed for evidence "
                    f"from the {words}, so no finding does not mean no fault.")
        return bounds_sentence(self.bounds, [(f.fault, f.hop, f.camera or "") for f in self.findings])

    def _motion_verdict(self, summary: dict[str, Any]) -> str:
        return motion_verdict(self.findings, self.bounds, self.camera_motion, summary["median"])

    def _rig_unobservable(self) -> str:
        """What a rig's evidence cannot check, for the verdict ("" for one camera, or when it sees everything)."""
        if self.rig is None:
            return ""
        unseen = [u.removeprefix("not observable: ") for u in self.rig.unobservable() if u.startswith("not observ")]
        return f"; not observable here: {'; '.join(unseen)}" if unseen else ""

    def to_json(self) -> dict[str, Any]:
        """The attribution.json contract (schema framechain/attribution@1)."""
        counts = self.counts()
        frames = self.config.frames
        return {
            "schema": SCHEMA,
            "source": self.source,
            "frames": {"camera": frames.camera, "body": frames.body, "world": frames.world},
            "observations": counts,
            "error_m": self.error_summary(),
            "residual_m": self.error_summary(self.error_after),
            "verdict": self.verdict,
            "inconclusive": bool(self.undetermined),
            "undetermined": [u.to_json() for u in self.undetermined],
            "tolerance_m": self.config.tolerance_m,
            "findings": [f.to_json() for f in self.findings],
            "hops": self.hop_summary(),
            "bounds": [b.to_json() for b in self.bounds],
            "curves": [c.to_json() for c in self.curves],
            "labels": self.labels.to_json(),
            **({"rig": self.rig.to_json()} if self.rig is not None else {}),
            "notes": list(self.notes),
            **({"camera_motion": list(self.camera_motion)} if self.camera_motion else {}),
        }


#: What an unexplained camera leaves undetermined (:func:`motion_undetermined`).
UNEXPLAINED_MOTION = "its motion against forward kinematics"


def motion_undetermined(entries: Sequence[Mapping[str, Any]]) -> tuple[Undetermined, ...]:
    """What the cameras' motion leaves undecided (the verdict is "Inconclusive: ..." with any): each camera whose
    motion the model does not explain, and each undetermined estimate of a camera it does explain."""
    out = []
    for entry in entries:
        camera = str(entry["camera"])
        if entry.get("explained") is False:
            out.append(Undetermined(UNEXPLAINED_MOTION, str(entry["unexplained_why"]), camera))
            continue
        out.extend(Undetermined(f"its {fault}", str(why), camera) for fault, why in (entry.get("undetermined") or
                                                                                    {}).items())
    return tuple(out)


def any_observable(entries: Sequence[Mapping[str, Any]]) -> bool:
    """Some camera's own motion shows some fault family (its ``camera_motion`` entry's ``observable`` flags)."""
    return any(o["observable"] for entry in entries for o in entry.get("observable", ()))


def motion_verdict(findings: Sequence[Finding], bounds: Sequence[Bound], camera_motion: Sequence[Mapping[str, Any]],
                   median_deg_s: float | None) -> str:
    """The verdict of a run measured by the cameras' own motion against forward kinematics: the findings, or
    "Inconclusive" when a camera's motion is not explained or the estimates that would decide are
    undetermined, or no fault beyond noise, or nothing could be checked; then the bounds."""
    rate = "" if median_deg_s is None else f" (median {median_deg_s:.2f} deg/s)"
    sentence = bounds_sentence(bounds, [(f.fault, f.hop, f.camera or "") for f in findings]) if bounds else ""
    then = f" {sentence}" if sentence else ""
    undecided = motion_undetermined(camera_motion)
    unexplained = [u.why for u in undecided if u.what == UNEXPLAINED_MOTION]
    undetermined = [f"camera {u.camera}: {u.why}" for u in undecided if u.what != UNEXPLAINED_MOTION]
    if not findings and not any_observable(camera_motion) and not undecided:
        if sentence:
            return ("Nothing could be checked: no camera's own motion can be measured against forward kinematics; "
                    f"{sentence[0].lower()}{sentence[1:]}")
        why = next((o["why"] for e in camera_motion for o in e.get("observable", ()) if o["why"]), "")
        return f"Not observable: no camera's own motion can be measured against forward kinematics ({why})."
    if not findings:
        if unexplained or undetermined:
            return f"Inconclusive: {'; '.join([*unexplained, *undetermined])}; no fix is offered.{then}"
        return f"No fault beyond noise: the cameras turn as forward kinematics says{rate}.{then}"
    top = findings[0]
    more = f", plus {len(findings) - 1} more" if len(findings) > 1 else ""
    on = f" on camera {top.camera}" if top.camera else ""
    found = (f"{top.fault.value} at {top.hop.value}{on} ({format_estimate(top.estimate)}) explains {top.share:.0%} "
             f"of the camera's rotation-rate misfit against forward kinematics{rate}{more}")
    if unexplained or undetermined:  # as the chain fit's: what is undecided first, then the fits that hold
        return (f"Inconclusive: {'; '.join([*unexplained, *undetermined])}; no fix is offered for it; of the fits "
                f"that hold, {found}.{then}")
    return f"{found}.{then}"


__all__ = ["SCHEMA", "UNEXPLAINED_MOTION", "AnalysisError", "Attribution", "Finding", "Metric", "Unattributed",
           "any_observable", "as_note", "as_undetermined", "gate_by_effect", "motion_undetermined", "motion_verdict"]
