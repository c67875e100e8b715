"""What each camera's own motion says, as findings: time offset, mount rotation, carrying link, focal length.

Each camera's fit (:mod:`framechain.analysis.egomotion.run`) proposes corrections of what the run
declares: the video/state time offset (``latency`` on camera_to_body), the mount's rotation on its
link (``rotation_error``, ``missing_rotation`` or ``axis_flip``), the link the camera moves with
(``wrong_camera_frame``: another link, another arm) and, when it is clear, the focal length
(``intrinsics``; otherwise a note). A correction is a finding when its estimate is determined, its
interval excludes "nothing wrong" and its size passes its bound (:mod:`framechain.analysis.egomotion.
bounds`), and only when the fitted model explains the camera's motion at all: a model that
leaves most of the motion unexplained offers no fix, whatever its estimates say.

The error they share is the camera's rotation-rate misfit: per frame pair, the measured rotation
against the rotation forward kinematics predicts as declared (declared link and mount, no offset),
in deg/s; its robust RMS over the pairs is the camera's error. Shares are Shapley values of the
misfit each correction removes (every subset of the corrections applied, as attribution does for
points): they say how much of the misfit each finding explains, not whether it is one.

Every fix names the key to change in the file that declares the camera (robot.yaml, or the
camera's calibration file), in that file's own form.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from framechain.analysis.egomotion import EgoMotionFit, RotationRates, rotation_rates
from framechain.analysis.egomotion.bounds import (
    FOCAL_CLEAR,
    NO_DEPTH,
    Judgement,
    focal_clear,
    judge,
    latency_bound_s,
    motion_bounds,
    mount_bound_deg,
    observability,
)
from framechain.analysis.egomotion.run import CameraMotion, CameraMotionEvidence
from framechain.analysis.fit.shapley import shapley_values
from framechain.analysis.model.estimates import (
    Estimate,
    FrameEstimate,
    LatencyEstimate,
    PermutationEstimate,
    RotationEstimate,
    ScaleEstimate,
    format_estimate,
)
from framechain.analysis.verdict.checks import Bound, bound_family
from framechain.analysis.verdict.findings import Finding
from framechain.arrays import FloatArray
from framechain.catalogue import Fault, HopName
from framechain.geometry.conventions import OPTICAL_FROM_LINK_QUAT_XYZW
from framechain.geometry.rotations import Inverse, Rotations, angle_of, matrix_of, rpy_of

__all__ = ["CameraDeclaration", "MotionFindings", "motion_findings", "yaml_mount"]

#: Every correction a camera's fit can propose.
_EVERY = frozenset({"latency", "link", "mount", "focal"})
#: Declared intrinsics the motion implies are off by less than this (ratio) get no note: the rotation
#: measured from images of a scene at finite depth comes out up to about 1% off on clean generated episodes.
FOCAL_NOTE = 0.03
#: Off a signed axis permutation by less than this (deg): the mount's axes were swapped or flipped.
FLIP_TOLERANCE_DEG = 10.0
_OPTICAL_FROM_LINK = np.asarray(OPTICAL_FROM_LINK_QUAT_XYZW)


@dataclass(frozen=True)
class CameraDeclaration:
    """Where a camera is declared (robot.yaml or its calibration file) and what that file says of it, as the
    episode's metadata carries it: fixes are written in that file's keys and form. Not a mount
    (:class:`framechain.config.mount.Mount`): of the camera's mount it keeps whether it is optical and its
    position, with the camera's timing offset and focal length."""

    name: str
    source: str  # the file declaring the mount and timing
    in_robot_yaml: bool  # declared inline under robot.yaml's cameras (keys are cameras.<name>.*)
    optical: bool  # the mount gives the optical frame (else a camera_link, with the REP-103 rotation below)
    xyz: tuple[float, float, float]
    timing_offset_s: float
    focal_px: tuple[float, float] | None = None  # the declared fx, fy

    @classmethod
    def from_metadata(cls, metadata: Mapping[str, Any], camera: str) -> CameraDeclaration | None:
        """The declaration of the camera whose optical frame is ``camera`` (a LeRobot episode's metadata)."""
        cameras = metadata.get("cameras")
        if not isinstance(cameras, Mapping):
            return None
        for name, entry in cameras.items():
            if isinstance(entry, Mapping) and entry.get("frame") == camera:
                source = str(entry.get("source") or metadata.get("robot_config") or "robot.yaml")
                xyz = tuple(float(v) for v in entry.get("xyz") or (0.0, 0.0, 0.0))
                timing = entry.get("timing") or {}
                focal = entry.get("focal_px")
                return cls(name=str(name), source=source, in_robot_yaml=source == metadata.get("robot_config"),
                           optical=bool(entry.get("optical_mount", True)), xyz=(xyz[0], xyz[1], xyz[2]),
                           timing_offset_s=float(timing.get("offset_s") or 0.0),
                           focal_px=None if not focal else (float(focal[0]), float(focal[1])))
        return None

    def key(self, leaf: str) -> str:
        return f"cameras.{self.name}.{leaf}" if self.in_robot_yaml else leaf


@dataclass(frozen=True)
class MotionFindings:
    """The cameras' findings (largest share first), the misfit before and after, notes and JSON entries."""

    findings: tuple[Finding, ...]
    residual_before: FloatArray  # (P,) deg/s per frame pair, every observable camera
    residual_after: FloatArray
    notes: tuple[str, ...]
    entries: tuple[dict[str, Any], ...]  # attribution.json ``camera_motion``
    bounds: tuple[Bound, ...] = ()  # per camera: what its motion can show (:func:`motion_bounds`)


@dataclass(frozen=True)
class _Proposal:
    """One correction a camera's fit proposes, before its share is known."""

    kind: str  # latency | link | mount | focal
    fault: Fault
    hop: HopName
    estimate: Estimate
    interval: dict[str, list[float]]
    confidence: float
    evidence: str
    fix: str


@dataclass(frozen=True)
class _Misfit:
    """The rotation-rate misfit of one camera under any subset of its corrections."""

    motion: CameraMotion
    fit: EgoMotionFit
    weights: FloatArray
    rows: np.ndarray
    #: The rates of every pair under each subset asked for so far: Shapley values ask for each subset many times.
    rates_by_kinds: dict[frozenset[str], RotationRates] = field(default_factory=dict, compare=False, repr=False)

    def rates(self, kinds: frozenset[str]) -> RotationRates:
        """Measured and predicted rates of every pair with the corrections ``kinds`` applied, the rest as declared."""
        if kinds not in self.rates_by_kinds:
            m, fit = self.motion, self.fit
            moved = "link" in kinds and fit.link != m.declared_link
            link = m.link_motion(fit.link if moved else m.declared_link)
            mount = fit.q_link_cam if moved or "mount" in kinds else m.declared_q_link_cam
            # The table was measured with the focal length scaled by measured_focal: undo it to see the declared one.
            focal = fit.focal_scale if "focal" in kinds else 1.0
            self.rates_by_kinds[kinds] = rotation_rates(m.table, link, mount,
                                                        fit.offset_s if "latency" in kinds else 0.0,
                                                        focal_scale=focal / m.measured_focal)
        return self.rates_by_kinds[kinds]

    def residual(self, kinds: frozenset[str]) -> FloatArray:
        """Per pair (deg/s) with the corrections ``kinds`` applied and the rest as declared."""
        out: FloatArray = np.rad2deg(self.rates(kinds).residual[self.rows])
        return out

    def rms(self, kinds: frozenset[str]) -> float:
        r = self.residual(kinds)
        return float(np.sqrt((self.weights * r**2).sum() / self.weights.sum()))

    def motion_rms(self) -> float:
        """The camera's rotation rate (deg/s, RMS over the pairs): the larger of measured and fitted."""
        rates = self.rates(_EVERY)  # every correction: the fitted link, mount, offset and focal length
        size = np.maximum(np.linalg.norm(rates.measured, axis=1), np.linalg.norm(rates.predicted, axis=1))[self.rows]
        return float(np.rad2deg(np.sqrt(np.nanmean(size**2)))) if size.size else 0.0


def motion_findings(evidence: CameraMotionEvidence, metadata: Mapping[str, Any]) -> MotionFindings:
    """Findings of every camera whose motion was measured and is explained, with shares of their summed misfit."""
    found: list[tuple[_Proposal, float, str]] = []
    before: list[FloatArray] = []
    after: list[FloatArray] = []
    notes: list[str] = []
    entries: list[dict[str, Any]] = []
    bounds: list[Bound] = []
    totals = 0.0
    for motion in evidence.cameras:
        declaration = CameraDeclaration.from_metadata(metadata, motion.camera)
        misfit = _misfit(motion, motion.fit) if motion.observable and motion.fit is not None else None
        if misfit is None or misfit.rows.size == 0:
            why = [] if misfit is None else [f"camera {motion.camera}: no measured frame pair inside the span of its "
                                             "links' poses"]
            notes.extend((*why, *(motion.notes if not motion.fit else motion.fit.notes)))
            entries.append(_entry(motion, declaration, None, (), None))
            bounds.extend(motion_bounds(motion))
            continue
        fit = misfit.fit
        judgement = judge(motion, fit, misfit.rms(frozenset()), misfit.rms(_EVERY), misfit.motion_rms())
        proposals, dropped = _contributing(misfit, _proposals(motion, fit, declaration, judgement))
        values = _shares(misfit, [p.kind for p in proposals])
        totals += misfit.rms(frozenset())
        before.append(misfit.residual(frozenset()))
        after.append(misfit.residual(frozenset(p.kind for p in proposals)))
        found.extend((proposal, value, motion.camera) for proposal, value in zip(proposals, values, strict=True))
        said = (*motion.notes, *fit.notes, *_judged_notes(motion.camera, judgement, (*motion.notes, *fit.notes)),
                *_focal_notes(motion, fit, proposals, judgement),
                *(_dropped_note(motion.camera, proposal, share) for proposal, share in dropped))
        notes.extend(n for n in said if n not in notes)
        entries.append(_entry(motion, declaration, misfit, proposals, judgement))
        bounds.extend(_not_told_apart(bound, dropped) for bound in motion_bounds(motion, judgement))
    findings = sorted((_finding(proposal, value, camera, totals) for proposal, value, camera in found),
                      key=lambda f: f.share, reverse=True)
    empty = np.zeros(0)
    return MotionFindings(findings=tuple(findings), residual_before=np.concatenate(before) if before else empty,
                          residual_after=np.concatenate(after) if after else empty, notes=tuple(notes),
                          entries=tuple(entries), bounds=(*bounds, NO_DEPTH))


def _finding(proposal: _Proposal, value: float, camera: str, total: float) -> Finding:
    return Finding(fault=proposal.fault, hop=proposal.hop, estimate=proposal.estimate, interval=proposal.interval,
                   share=value / total if total > 0 else 0.0, error_m=value, confidence=proposal.confidence,
                   evidence=proposal.evidence, fix=proposal.fix, model=f"camera_motion_{proposal.kind}", camera=camera,
                   error_unit="deg/s")


def _judged_notes(camera: str, judgement: Judgement, said: Sequence[str]) -> list[str]:
    """A motion the model does not explain, and each undetermined estimate whose reason the fit's notes (``said``)
    do not give already, as notes."""
    out = [f"{judgement.why_unexplained}: no fix is offered from it"] if not judgement.explained else []
    return out + [f"camera {camera}: {text}" for text in judgement.undetermined.values()
                  if not any(text.split(": ", 1)[-1] in note for note in said)]


def _misfit(motion: CameraMotion, fit: EgoMotionFit) -> _Misfit:
    """The pairs every subset can predict, weighted robustly by their misfit with every correction applied."""
    probe = _Misfit(motion, fit, np.ones(len(motion.table)), np.arange(len(motion.table)))
    corrected = probe.residual(frozenset({"latency", "link", "mount", "focal"}))
    plain = probe.residual(frozenset())
    rows = np.flatnonzero(np.isfinite(corrected) & np.isfinite(plain))
    scale = max(1.4826 * float(np.median(corrected[rows])) if rows.size else 0.0, 0.05)
    weights = 1.0 / (1.0 + (corrected[rows] / (2.5 * scale)) ** 2)
    return _Misfit(motion, fit, weights, rows, probe.rates_by_kinds)


def _contributing(misfit: _Misfit, proposals: Sequence[_Proposal]
                  ) -> tuple[list[_Proposal], list[tuple[_Proposal, float]]]:
    """The corrections that lower the misfit given the others (a Shapley share above zero), and each one dropped with
    its share: the least contributing first, the shares recomputed without it (as the chain fit's findings)."""
    kept = list(proposals)
    dropped = []
    while kept:
        values = _shares(misfit, [p.kind for p in kept])
        worst = int(np.argmin(values))
        if values[worst] > 0:
            break
        dropped.append((kept.pop(worst), float(values[worst])))
    return kept, dropped


def _dropped_note(camera: str, proposal: _Proposal, share: float) -> str:
    return (f"camera {camera}: {proposal.fault.value} at {proposal.hop} ({format_estimate(proposal.estimate)}) is no "
            f"finding: with the other corrections it does not lower the rotation-rate misfit (Shapley share "
            f"{share:+.2f} deg/s)")


def _not_told_apart(bound: Bound, dropped: Sequence[tuple[_Proposal, float]]) -> Bound:
    """A family whose correction was dropped bounds nothing: its fit is not told apart from the others (never "no
    fault above B" beside an estimate larger than B)."""
    for proposal, _share in dropped:
        if bound_family(proposal.fault) == bound_family(bound.fault):
            return replace(bound, observable=False, min_detectable=None, statistical=None,
                           why=f"camera {bound.camera or 'its'}: its fit ({format_estimate(proposal.estimate)}) is not "
                               "told apart from the other corrections")
    return bound


def _shares(misfit: _Misfit, kinds: Sequence[str]) -> list[float]:
    """Each correction's Shapley value of the misfit removed (deg/s), over every subset of the others."""
    return shapley_values(len(kinds), lambda s: misfit.rms(frozenset()) - misfit.rms(frozenset(kinds[i] for i in s)))


# -- the corrections proposed ----------------------------------------------------------------------
def _proposals(motion: CameraMotion, fit: EgoMotionFit, declaration: CameraDeclaration | None,
               judgement: Judgement) -> list[_Proposal]:
    """The corrections that are findings: determined, clear of "nothing wrong", past their bound; none at all
    when the fitted model does not explain the motion."""
    if not judgement.explained or fit.unobservable:
        return []
    undetermined = judgement.undetermined
    out: list[_Proposal] = []
    low, high = fit.offset_interval_s
    if (Fault.LATENCY.value not in undetermined and fit.offset_observable and (low > 0 or high < 0)
            and abs(fit.offset_s) >= latency_bound_s(fit)):
        out.append(_latency(motion, fit, declaration))
    if fit.wrong_link:
        out.append(_link(motion, fit, declaration))
    elif (fit.mount_error is not None and fit.mount_observable and Fault.ROTATION_ERROR.value not in undetermined
          and fit.mount_error.angle_deg >= mount_bound_deg(fit)):
        out.append(_mount(motion, fit, declaration))
    scale_low, scale_high = fit.focal_scale_interval
    if (Fault.INTRINSICS.value not in undetermined and abs(fit.focal_scale - 1.0) > focal_clear(motion)
            and scale_high - scale_low < FOCAL_CLEAR and not scale_low <= 1.0 <= scale_high):
        out.append(_focal(motion, fit, declaration))
    return out


def _focal_notes(motion: CameraMotion, fit: EgoMotionFit, proposals: Sequence[_Proposal],
                 judgement: Judgement) -> list[str]:
    """The focal length the camera's motion implies, as a note when it is no finding (assumed intrinsics, or a
    departure not clear enough to fix); nothing when it is undetermined (said already)."""
    low, high = fit.focal_scale_interval
    if (any(p.kind == "focal" for p in proposals) or not np.isfinite(fit.focal_scale)
            or Fault.INTRINSICS.value in judgement.undetermined or not judgement.explained):
        return []
    implied = f"{fit.focal_scale:.3f} ({low:.3f} .. {high:.3f}) times the declared focal length"
    if not motion.intrinsics_known:
        return [f"camera {motion.camera}: its motion implies a focal length {implied} (intrinsics assumed)"]
    if not low <= 1.0 <= high and abs(fit.focal_scale - 1.0) > FOCAL_NOTE:
        return [f"camera {motion.camera}: its motion implies a focal length {implied}; not clear enough to fix, "
                "calibrate the intrinsics to be sure"]
    return []


def _latency(motion: CameraMotion, fit: EgoMotionFit, declaration: CameraDeclaration | None) -> _Proposal:
    ms = fit.offset_s * 1e3
    when = "before" if ms < 0 else "after"
    evidence = (f"the images of {motion.camera} turn as {fit.link} did {abs(ms):.1f} ms {when} their stamps "
                f"({motion.frames} frames, {len(motion.table)} frame pairs against forward kinematics)")
    if declaration is not None:
        new = declaration.timing_offset_s + fit.offset_s
        fix = (f"In {declaration.source}, set {declaration.key('timing.offset_s')}: {new:.3f} (now "
               f"{declaration.timing_offset_s:.3f}): its frames show the robot {abs(ms):.1f} ms {when} the state "
               "row they are stored with.")
    else:
        fix = (f"The images of {motion.camera} are stamped {abs(ms):.1f} ms {'late' if ms < 0 else 'early'} against "
               f"the transforms: correct the camera's time offset (stamp its images {abs(ms):.1f} ms "
               f"{'earlier' if ms < 0 else 'later'}).")
    return _Proposal("latency", Fault.LATENCY, HopName.CAMERA_TO_BODY, LatencyEstimate(offset_s=fit.offset_s),
                     {"offset_s": list(fit.offset_interval_s)}, 0.95, evidence, fix)


def _link(motion: CameraMotion, fit: EgoMotionFit, declaration: CameraDeclaration | None) -> _Proposal:
    declared = next((f for f in fit.links if f.link == motion.declared_link), None)
    best = fit.links[0]
    ratio = best.residual_deg / declared.residual_deg if declared is not None and declared.residual_deg > 0 else 0.0
    evidence = (f"the images of {motion.camera} turn as {fit.link} does "
                f"({best.residual_deg:.3f} deg misfit per frame pair), not as the declared {motion.declared_link}"
                + (f" ({declared.residual_deg:.3f} deg)" if declared is not None else ""))
    mount = yaml_mount(fit.link, fit.q_link_cam, _position(motion, declaration), declaration)
    if declaration is not None:
        fix = (f"In {declaration.source}, mount camera {declaration.name} on {fit.link}: "
               f"{declaration.key('mount')}: {mount}.")
    else:
        fix = f"Hang {motion.camera} from {fit.link}, not {motion.declared_link}: {mount}."
    return _Proposal("link", Fault.WRONG_CAMERA_FRAME, HopName.CAMERA_TO_BODY,
                     FrameEstimate(used=motion.declared_link, meant=fit.link, hop=HopName.CAMERA_TO_BODY.value),
                     {}, float(np.clip(1.0 - ratio, 0.0, 0.99)), evidence, fix)


def _mount(motion: CameraMotion, fit: EgoMotionFit, declaration: CameraDeclaration | None) -> _Proposal:
    error = fit.mount_error
    assert error is not None
    fault, estimate = _mount_fault(motion, fit, declaration)
    declared = ("the placeholder mount of the robot.yaml framechain made (the mount measured, not a fault found)"
                if motion.guessed else "the declared mount")
    evidence = (f"the images of {motion.camera} turn about axes {error.angle_deg:.2f} deg away from those "
                f"{motion.declared_link}'s turns give through {declared}")
    mount = yaml_mount(motion.declared_link, fit.q_link_cam, _position(motion, declaration), declaration)
    if declaration is not None:
        fix = f"In {declaration.source}, set {declaration.key('mount')}: {mount} (the mount the images show)."
    else:
        fix = f"Publish the measured mount of {motion.camera}: {mount}."
    return _Proposal("mount", fault, HopName.CAMERA_TO_BODY, estimate, {"angle_deg": list(error.interval_deg)}, 0.95,
                     evidence, fix)


def _mount_fault(motion: CameraMotion, fit: EgoMotionFit,
                 declaration: CameraDeclaration | None) -> tuple[Fault, Estimate]:
    """axis_flip (the mounts differ by a signed axis permutation), missing_rotation (the declared mount has
    no rotation of its own) or rotation_error."""
    error = fit.mount_error
    assert error is not None
    declared = motion.declared_q_link_cam
    change = matrix_of((Inverse(declared), fit.q_link_cam))
    permutation = np.round(change)
    is_permutation = bool((np.abs(permutation).sum(axis=0) == 1).all() and (np.abs(permutation).sum(axis=1) == 1).all())
    off = np.rad2deg(angle_of((Inverse(change), permutation))) \
        if is_permutation and np.isclose(np.linalg.det(permutation), 1.0) else 180.0
    if error.angle_deg > 45.0 and off < FLIP_TOLERANCE_DEG:
        rows = tuple((int(row[0]), int(row[1]), int(row[2])) for row in permutation.astype(int))
        return Fault.AXIS_FLIP, PermutationEstimate(permutation=rows)
    optical = declaration.optical if declaration is not None else True
    own: Rotations = declared if optical else (declared, Inverse(_OPTICAL_FROM_LINK))
    fault = Fault.MISSING_ROTATION if np.rad2deg(angle_of(own)) < 0.5 else Fault.ROTATION_ERROR
    return fault, RotationEstimate(angle_deg=error.angle_deg, axis=error.axis, axis_frame=motion.camera,
                                   faulty="recorded data")


def _focal(motion: CameraMotion, fit: EgoMotionFit, declaration: CameraDeclaration | None) -> _Proposal:
    scale = 1.0 / fit.focal_scale
    low, high = fit.focal_scale_interval
    evidence = (f"the images of {motion.camera} turn {1.0 / fit.focal_scale:.3f} times as far across the optical axis "
                f"as {fit.link} does (measured with the declared focal length): it is {scale:.3f} times the true one")
    implied = f"a focal length {fit.focal_scale:.3f} times the declared one"
    if declaration is not None and declaration.focal_px is not None:
        fx, fy = (v * fit.focal_scale for v in declaration.focal_px)
        fix = (f"In {declaration.source}, set {declaration.key('intrinsics.fx')}: {fx:.1f} and "
               f"{declaration.key('intrinsics.fy')}: {fy:.1f} (its motion implies {implied}); better, calibrate the "
               "camera.")
    else:
        fix = f"Calibrate {motion.camera}'s intrinsics: its motion implies {implied}."
    return _Proposal("focal", Fault.INTRINSICS, HopName.PIXEL_TO_CAMERA,
                     ScaleEstimate(name="scale", value=scale, variant="focal"), {"scale": [1.0 / high, 1.0 / low]},
                     0.95, evidence, fix)


def _position(motion: CameraMotion, declaration: CameraDeclaration | None) -> tuple[float, ...]:
    """The camera's position on its link as the fix writes it: fitted when it was not known, else as the file has
    it."""
    if declaration is not None and motion.position is None:
        return declaration.xyz
    return tuple(float(v) for v in motion.xyz_link_cam)


def yaml_mount(link: str, q_link_cam: FloatArray, position: tuple[float, ...],
                declaration: CameraDeclaration | None) -> str:
    """A mount as robot.yaml / a calibration file writes it: ``{parent, xyz, rpy, optical}`` (optical without a
    declaration: the mount of the camera's optical frame)."""
    optical = declaration.optical if declaration is not None else True
    rotation: Rotations = q_link_cam
    if not optical:  # the file gives camera_link; the optical rotation hangs below it
        rotation = (q_link_cam, Inverse(_OPTICAL_FROM_LINK))
    rpy = rpy_of(rotation)
    return (f"{{parent: {link}, xyz: [{', '.join(f'{v:.4f}' for v in position)}], "
            f"rpy: [{', '.join(f'{v:.5f}' for v in rpy)}], optical: {str(optical).lower()}}}")


# -- the JSON entry ---------------------------------------------------------------------------------
def _entry(motion: CameraMotion, declaration: CameraDeclaration | None, misfit: _Misfit | None,
           proposals: Sequence[_Proposal], judgement: Judgement | None) -> dict[str, Any]:
    """One camera's ``camera_motion`` entry: the measurement, and what it can and cannot observe."""
    fit = motion.fit
    entry: dict[str, Any] = {
        "camera": motion.camera, "name": declaration.name if declaration else None,
        "declared_link": motion.declared_link, "frames": motion.frames, "pairs": len(motion.table),
        # pairs + the left-out counts = pairs_possible (the usable frames' pairs ``spans`` apart)
        "pairs_possible": None if motion.pair_counts is None else motion.pair_counts.possible,
        "pairs_left_out": motion.pairs_left_out(),
        "seconds": round(motion.seconds, 3), "pairing": motion.pairing or None,
        # The lens the motion was measured through: declared, or guessed (intrinsics_known false).
        "focal_px": _num(motion.focal_px), "width_px": motion.width_px, "intrinsics_known": motion.intrinsics_known,
        "observable": observability(motion, judgement),
    }
    if fit is None or not fit.link:
        return {**entry, "notes": list(motion.notes if fit is None else (*motion.notes, *fit.notes))}
    error = fit.mount_error
    entry.update({
        "link": fit.link, "alternatives": list(fit.alternatives),
        "offset_s": _num(fit.offset_s), "offset_interval_s": [_num(v) for v in fit.offset_interval_s],
        "q_link_cam": [_num(v) for v in fit.q_link_cam],
        "mount_error_deg": None if error is None else _num(error.angle_deg),
        "mount_error_interval_deg": None if error is None else [_num(v) for v in error.interval_deg],
        "mount_error_axis": None if error is None else [_num(v) for v in error.axis],
        "focal_scale": _num(fit.focal_scale), "focal_scale_interval": [_num(v) for v in fit.focal_scale_interval],
        "rotation_deg_per_pair": _num(fit.camera_rotation_deg),
        "corrections": [p.kind for p in proposals],
        "notes": list(dict.fromkeys((*motion.notes, *fit.notes))),
        "link_misfits": {name: _num(value) for name, value in fit.link_misfits},
    })
    if motion.position is not None:  # not known: fitted from the camera's matches (:mod:`.position`)
        position = motion.position
        entry["position"] = {"link": position.link, "xyz_link_cam": [_num(v) for v in position.xyz_link_cam],
                             "focal_px": _num(position.focal_factor * motion.focal_px),
                             "residual_px": {"at_link_origin": _num(position.residual_px[0]),
                                             "fitted": _num(position.residual_px[1])},
                             "pairs": position.pairs, "matches": position.matches,
                             # 1 sd along the principal axis it is known least along (a unit vector of the link)
                             "spread_m": _num(position.spread_m[0]),
                             "spread_axis": [_num(v) for v in position.spread_axes[0]]}
    if fit.evidence is not None:
        entry["mount_evidence"] = {**fit.evidence.to_json(),
                                   "declared_q_link_cam": [_num(v) for v in motion.declared_q_link_cam]}
    if misfit is not None:
        entry["misfit_deg_s"] = {"declared": _num(misfit.rms(frozenset())),
                                 "corrected": _num(misfit.rms(frozenset(p.kind for p in proposals))),
                                 "fitted": _num(misfit.rms(_EVERY))}
    if judgement is not None:
        entry["explained"] = judgement.explained
        entry["unexplained_why"] = judgement.why_unexplained or None
        entry["motion_deg_s"] = _num(judgement.motion_deg_s)
        entry["undetermined"] = dict(judgement.undetermined)
    return entry


def _num(value: float) -> float | None:
    return round(float(value), 6) if np.isfinite(value) else None
