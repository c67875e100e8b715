"""The cameras' own motion in an attribution: the evidence of a run that has nothing else, corroboration otherwise.

A run with points to measure the chain against (logged hops, a target, a reference, a static target)
is attributed from them; what each measured camera's motion says then travels with it as the
``camera_motion`` entries and notes (its metric is another one: shares do not mix). A run with none
(an episode as recorded: joint states and videos, no detections) is attributed from the cameras'
motion alone when some camera moves (a camera fixed in the world cannot stand in for them): metric
``camera_motion``, findings with shares of the rotation-rate misfit
(:mod:`framechain.analysis.egomotion.findings`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from framechain.analysis.egomotion.findings import motion_findings
from framechain.analysis.egomotion.run import CameraMotionEvidence
from framechain.analysis.evidence.replayed import Replayed
from framechain.analysis.model.chain import ChainInputs
from framechain.analysis.model.estimates import format_estimate
from framechain.analysis.verdict.findings import Attribution, motion_undetermined
from framechain.config.chain import ChainConfig
from framechain.geometry.camera import CameraModel
from framechain.timeline import CameraTable, Timeline

__all__ = ["with_camera_motion"]


def with_camera_motion(replayed: Replayed, chain: ChainConfig, attribution: Attribution | None,
                       evidence: CameraMotionEvidence, *, seed: int = 0) -> Attribution:
    """``attribution`` (None: there is none) with what the cameras' motion says (see the module docstring)."""
    metadata = replayed.timeline.metadata
    moving = any(c.fit is not None for c in evidence.cameras)
    if attribution is not None and (attribution.metric != "none" or not moving):
        measured = CameraMotionEvidence(cameras=tuple(c for c in evidence.cameras if c.fit is not None))
        if not measured.cameras:
            return attribution
        found = motion_findings(measured, metadata)
        metric = attribution.metric.replace("_", " ")
        said = [f"camera motion: {f.fault.value} on camera {f.camera} ({format_estimate(f.estimate)}), measured "
                f"against forward kinematics, not a share of the {metric} error" for f in found.findings]
        notes = (*attribution.notes, *said, *(n for n in found.notes if n not in attribution.notes))
        return replace(attribution, camera_motion=found.entries, notes=notes)
    base = attribution or _unmeasured(replayed, chain, seed)
    found = motion_findings(evidence, metadata)
    notes = tuple(n for n in base.notes if not n.startswith("no evidence:"))
    if not evidence.observable:
        why = "; ".join(dict.fromkeys(c.why_not for c in evidence.cameras if c.why_not))
        notes += ("no evidence: no camera's own motion could be measured against forward kinematics "
                  f"({why or 'see camera_motion'}) and the log has no points to measure the chain against",)
    return replace(base, metric="camera_motion", stage="camera_rotation_rate", findings=found.findings,
                   others_shift=(), camera_motion=found.entries, undetermined=motion_undetermined(found.entries),
                   rate_residual=(found.residual_before, found.residual_after), bounds=found.bounds, curves=(),
                   notes=(*notes, *(n for n in found.notes if n not in notes)))


def _unmeasured(replayed: Replayed, chain: ChainConfig, seed: int) -> Attribution:
    """An attribution with nothing measured yet: the replay as it is (no observation, or none replayed)."""
    result = replayed.replay
    inputs = ChainInputs.from_replay(result, replayed.buffer, _camera_model(replayed.timeline, chain))
    n = len(inputs)
    return Attribution(
        source=dict(replayed.timeline.metadata.get("source", {"path": "", "format": "unknown"})), config=chain,
        replay=result, inputs=inputs, metric="none", error_before=np.full(n, np.nan), error_after=np.full(n, np.nan),
        hop_errors={}, evidence_points=np.full((n, 3), np.nan), corrected_world=np.full((n, 3), np.nan), findings=(),
        seed=seed, aligned=replayed.aligned, notes=(*replayed.buffer.warnings, *replayed.notes),
    )


def _camera_model(timeline: Timeline, chain: ChainConfig) -> CameraModel:
    """The chain camera's model, else any camera's, else a unit model (nothing is projected with it)."""
    cams = timeline.cameras
    rows = np.flatnonzero(cams.frame == chain.frames.camera)
    if rows.size == 0 and len(cams):
        rows = np.arange(1)
    if rows.size:
        return CameraModel.from_table(cams, int(rows[0]))
    return CameraModel.from_table(CameraTable.from_intrinsics(chain.frames.camera, fx=1.0, fy=1.0, cx=0.0, cy=0.0,
                                                              width=1, height=1), 0)
