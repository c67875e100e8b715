"""The fault catalogue as small composable models over the vectorised chain.

A :class:`FaultModel` maps a parameter vector to a change of the chain (a Perturbation). Models
in one ``family`` change the same thing (the camera-to-body rotation, say) and never combine.
Each model turns fitted parameters into the catalogue's estimate, either as fitted
(``mode="as_run"``: the parameters describe the chain that produced the evidence, as when the
robot's logged points are compared with the recorded data) or inverted (``mode="correction"``: the
parameters correct the recorded data towards the truth, so the fault is their inverse).
"""

from __future__ import annotations

import itertools
from dataclasses import replace
from typing import Literal

import numpy as np

from framechain.analysis.model.chain import ChainInputs, Perturbation
from framechain.analysis.model.estimates import (
    FrameEstimate,
    InvertedEstimate,
    LatencyEstimate,
    PermutationEstimate,
    RotationEstimate,
    ScaleEstimate,
    TranslationEstimate,
)
from framechain.analysis.model.fault import FaultModel, Mode
from framechain.analysis.model.frame_swaps import frame_swap_models
from framechain.arrays import FloatArray
from framechain.catalogue import Fault, HopName
from framechain.geometry.rotations import (
    quat_angle,
    quat_conjugate,
    quat_from_rotvec,
    quat_multiply,
    quat_rotate,
    quat_to_rotvec,
)

#: Below this angle two rotations are "the same" when naming missing_rotation (degrees).
SAME_ROTATION_DEG = 0.5


#: Time offsets searched (s): on real logs a stamp offset of half a second is not rare (a driver
#: stamping on arrival, a clock set by hand); fit.py searches the whole range, coarse then fine.
LATENCY_BOUND_S = 1.0


def _latency(hop: HopName) -> FaultModel:
    camera = hop == HopName.CAMERA_TO_BODY

    def apply(p: Perturbation, x: FloatArray) -> Perturbation:
        return replace(p, camera_offset_s=float(x[0])) if camera else replace(p, pose_offset_s=float(x[0]))

    return FaultModel(
        name=f"latency[{hop.value}]",
        fault=Fault.LATENCY,
        hop=hop,
        family=f"time:{hop.value}",
        x0=(0.0,),
        lower=(-LATENCY_BOUND_S,),
        upper=(LATENCY_BOUND_S,),
        x_scale=(0.01,),
        apply=apply,
        estimate=lambda x, mode, inputs: LatencyEstimate(offset_s=round(float(x[0]), 6)),
    )


def _rotation() -> FaultModel:
    def apply(p: Perturbation, x: FloatArray) -> Perturbation:
        return replace(p, rotvec_mount=np.asarray(x, dtype=float))

    def estimate(x: FloatArray, mode: Mode, inputs: ChainInputs) -> RotationEstimate:
        # The faulty mount relative to the correct one, axis in the mount's link frame.
        _fault, faulty = rotation_verdict(x, mode, inputs)
        rotvec = np.asarray(x, dtype=float) if faulty == "as_run" else -np.asarray(x, dtype=float)
        angle = float(np.linalg.norm(rotvec))
        axis = rotvec / angle if angle > 0 else np.array([0.0, 0.0, 1.0])
        frame = inputs.mount.link if inputs.mount is not None else inputs.frames.camera
        ax, ay, az = (round(float(a), 4) + 0.0 for a in axis)  # + 0.0 drops negative zeros
        return RotationEstimate(angle_deg=round(float(np.rad2deg(angle)), 4), axis=(ax, ay, az), axis_frame=frame,
                                faulty="recorded data" if faulty == "recorded" else "as run")

    return FaultModel(
        name="rotation[camera_to_body]",
        fault=Fault.ROTATION_ERROR,
        hop=HopName.CAMERA_TO_BODY,
        family="camera_rotation",
        x0=(0.0, 0.0, 0.0),
        lower=(-np.pi,) * 3,
        upper=(np.pi,) * 3,
        plausibility_bounds=False,
        x_scale=(0.05,) * 3,
        apply=apply,
        estimate=estimate,
    )


#: A camera mount's position may be off by at most this much (m) in a fit: a mount farther off is another frame
#: (a frame swap), and a fit that runs to it explains by moving the camera away from everything, not by a fault.
TRANSLATION_BOUND_M = 0.5
#: The fit's pull of a mount translation towards none (residual metres per metre): a millimetre's residual at a
#: metre, nothing beside the evidence's, but it keeps a direction the evidence cannot see at none.
TRANSLATION_RIDGE = 1e-3


def _translation() -> FaultModel:
    """The mount's position off: a constant offset in the mount's parent frame (the body without a static mount)."""

    def estimate(x: FloatArray, mode: Mode, inputs: ChainInputs) -> TranslationEstimate:
        # The faulty mount's position relative to the right one, in the mount's parent frame.
        offset = np.asarray(x, dtype=float) if mode == "as_run" else -np.asarray(x, dtype=float)
        frame = inputs.mount.parent if inputs.mount is not None else inputs.frames.body
        ox, oy, oz = (round(float(v), 6) + 0.0 for v in offset)  # + 0.0 drops negative zeros
        return TranslationEstimate(offset_m=(ox, oy, oz), frame=frame,
                                   faulty="as run" if mode == "as_run" else "recorded data")

    return FaultModel(
        name="translation[camera_to_body]",
        fault=Fault.TRANSLATION_ERROR,
        hop=HopName.CAMERA_TO_BODY,
        family="camera_translation",
        x0=(0.0, 0.0, 0.0),
        lower=(-TRANSLATION_BOUND_M,) * 3,
        upper=(TRANSLATION_BOUND_M,) * 3,
        x_scale=(0.01,) * 3,
        apply=lambda p, x: replace(p, translation_mount=np.asarray(x, dtype=float)),
        estimate=estimate,
        ridge=TRANSLATION_RIDGE,
    )


def _signed_permutations() -> list[FloatArray]:
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            m = np.zeros((3, 3))
            m[np.arange(3), perm] = signs
            if not np.array_equal(m, np.eye(3)):
                out.append(m)
    return out


def _axis_flip(perm: FloatArray) -> FaultModel:
    label = ",".join(
        f"{'+' if row[np.argmax(np.abs(row))] > 0 else '-'}{'xyz'[np.argmax(np.abs(row))]}" for row in perm
    )

    def estimate(x: FloatArray, mode: Mode, inputs: ChainInputs) -> PermutationEstimate:
        used = perm if mode == "as_run" else perm.T
        return PermutationEstimate(permutation=tuple((int(r[0]), int(r[1]), int(r[2])) for r in used))

    return FaultModel(
        name=f"axis_flip[{label}]",
        fault=Fault.AXIS_FLIP,
        hop=HopName.CAMERA_TO_BODY,
        family="camera_rotation",
        apply=lambda p, x: replace(p, permutation=perm),
        estimate=estimate,
        choice_penalty=float(np.log(47.0)),
    )


def _inverted(hop: HopName) -> FaultModel:
    camera = hop == HopName.CAMERA_TO_BODY

    def apply(p: Perturbation, x: FloatArray) -> Perturbation:
        return replace(p, invert_camera=True) if camera else replace(p, invert_pose=True)

    return FaultModel(
        name=f"inverted[{hop.value}]",
        fault=Fault.INVERTED_TRANSFORM,
        hop=hop,
        family="camera_rotation" if camera else f"pose_invert:{hop.value}",
        apply=apply,
        estimate=lambda x, mode, inputs: InvertedEstimate(hop=hop.value),
    )


def _inverted_edge(parent: str, child: str) -> FaultModel:
    """One recorded edge of the camera path published the wrong way round (T_a_b for T_b_a)."""
    return FaultModel(
        name=f"inverted[{parent}->{child}]",
        fault=Fault.INVERTED_TRANSFORM,
        hop=HopName.CAMERA_TO_BODY,
        family="camera_rotation",
        apply=lambda p, x: replace(p, invert_edge=child),
        estimate=lambda x, mode, inputs: InvertedEstimate(hop=HopName.CAMERA_TO_BODY.value, edge=(parent, child)),
    )


#: Scale bounds on a static target alone: shrinking the points towards the camera (a small depth
#: factor, or a long focal length that pulls every ray onto the axis) shrinks any spread, so beyond
#: these a fit only collapses the target; a fit that runs to them is not reported.
BLIND_SCALE_BOUNDS = (0.2, 5.0)


def _depth_scale(blind: bool = False) -> FaultModel:
    def estimate(x: FloatArray, mode: Mode, inputs: ChainInputs) -> ScaleEstimate:
        factor = float(x[0]) if mode == "as_run" else 1.0 / float(x[0])
        return ScaleEstimate(name="factor", value=round(factor, 6))

    return FaultModel(
        name="depth_scale",
        fault=Fault.DEPTH_SCALE,
        hop=HopName.PIXEL_TO_CAMERA,
        family="depth",
        x0=(1.0,),
        lower=(BLIND_SCALE_BOUNDS[0],) if blind else (1e-4,),
        upper=(BLIND_SCALE_BOUNDS[1],) if blind else (1e4,),
        x_scale=(0.01,),
        apply=lambda p, x: replace(p, depth_factor=float(x[0])),
        estimate=estimate,
        starts=((0.5,), (2.0,)) if blind else ((0.001,), (1000.0,), (0.5,), (2.0,)),
    )


def _intrinsics(variant: Literal["resolution", "focal"], blind: bool = False) -> FaultModel:
    """K of another resolution (focal length and principal point scale) or another lens (focal only)."""

    def estimate(x: FloatArray, mode: Mode, inputs: ChainInputs) -> ScaleEstimate:
        scale = float(x[0]) if mode == "as_run" else 1.0 / float(x[0])
        return ScaleEstimate(name="scale", value=round(scale, 6), variant=variant)

    def apply(p: Perturbation, x: FloatArray) -> Perturbation:
        s = float(x[0])
        return replace(p, focal_scale=s, principal_scale=s if variant == "resolution" else 1.0)

    return FaultModel(
        name=f"intrinsics[{variant}]",
        fault=Fault.INTRINSICS,
        hop=HopName.PIXEL_TO_CAMERA,
        family="intrinsics",
        x0=(1.0,),
        lower=(BLIND_SCALE_BOUNDS[0],) if blind else (0.05,),
        upper=(BLIND_SCALE_BOUNDS[1],) if blind else (20.0,),
        x_scale=(0.01,),
        apply=apply,
        estimate=estimate,
        starts=((0.5,), (2.0,), (1.5,), (0.75,)),
    )


def _wrong_world(alternative: str, configured: str) -> FaultModel:
    def estimate(x: FloatArray, mode: Mode, inputs: ChainInputs) -> FrameEstimate:
        return FrameEstimate(
            used=alternative if mode == "as_run" else configured,
            meant=configured if mode == "as_run" else alternative,
            hop=HopName.BODY_TO_WORLD.value,
        )

    return FaultModel(
        name=f"wrong_world_frame[{alternative}]",
        fault=Fault.WRONG_WORLD_FRAME,
        hop=HopName.BODY_TO_WORLD,
        family="world_frame",
        apply=lambda p, x: replace(p, world=alternative),
        estimate=estimate,
    )


def world_alternatives(inputs: ChainInputs) -> list[str]:
    """The other REP-105 world frames the body can be looked up in (map <-> odom)."""
    frames = set(inputs.buffer.frames)
    configured = inputs.frames.world
    out: list[str] = []
    for name in ("map", "odom", "odom_combined", "world"):
        if name != configured and name in frames and inputs.buffer.path(name, inputs.frames.body).connected:
            out.append(name)
    return out


def models_for(
    inputs: ChainInputs, hops: tuple[HopName, ...] | None = None, *, blind: bool = False
) -> list[FaultModel]:
    """Every fault hypothesis that applies to this chain (optionally only at some hops).

    ``blind`` drops the world-frame swap: the spread of a static target cannot say which world
    frame was meant (map and odom differ by a slow drift that moves every point alike); and it
    bounds the scales to :data:`BLIND_SCALE_BOUNDS`.
    """
    out: list[FaultModel] = [
        _depth_scale(blind),
        _intrinsics("resolution", blind),
        _intrinsics("focal", blind),
        _rotation(),
        _translation(),
        _latency(HopName.BODY_TO_WORLD),
    ]
    if inputs.camera_is_dynamic:
        out.append(_latency(HopName.CAMERA_TO_BODY))
    out += [_axis_flip(p) for p in _signed_permutations()]
    out += [_inverted(HopName.CAMERA_TO_BODY), _inverted(HopName.BODY_TO_WORLD)]
    camera_path = inputs.buffer.path(inputs.frames.body, inputs.frames.camera)
    if len(camera_path.hops) > 1:
        out += [_inverted_edge(h.parent, h.child) for h in camera_path.hops]
    if not blind:
        out += [_wrong_world(alt, inputs.frames.world) for alt in world_alternatives(inputs)]
    # Imported here: the frame swaps are fault models too (they build on this module).

    out += frame_swap_models(inputs, blind=blind)
    if hops is not None:
        out = [m for m in out if m.hop in hops]
    return out


def rotation_verdict(x: FloatArray, mode: Mode, inputs: ChainInputs) -> tuple[Fault, Literal["as_run", "recorded"]]:
    """missing_rotation or rotation_error, and which side's mount is wrong.

    A mount whose rotation is (nearly) none while the other side's is not lost its rotation: the
    robot's (as run) when the fitted mount is bare, the log's when the recorded one is.
    """
    mount = inputs.mount
    change = float(np.rad2deg(np.linalg.norm(x)))
    recorded_side: Literal["as_run", "recorded"] = "recorded" if mode == "correction" else "as_run"
    if mount is None or change <= SAME_ROTATION_DEG:
        return Fault.ROTATION_ERROR, recorded_side
    recorded = mount.q_parent_link
    fitted = quat_multiply(recorded, quat_from_rotvec(np.asarray(x, dtype=float)))
    if mode == "as_run" and np.rad2deg(quat_angle(fitted)) < SAME_ROTATION_DEG:
        return Fault.MISSING_ROTATION, "as_run"
    if np.rad2deg(quat_angle(recorded)) < SAME_ROTATION_DEG:
        return Fault.MISSING_ROTATION, "recorded"
    return Fault.ROTATION_ERROR, recorded_side


def classify_rotation(model: FaultModel, x: FloatArray, mode: Mode, inputs: ChainInputs) -> Fault:
    """The catalogue entry of a fitted model (rotation fits split into missing_rotation / rotation_error)."""
    if model.fault != Fault.ROTATION_ERROR or model.camera is not None:  # a rig camera's model words its own
        return model.fault
    return rotation_verdict(x, mode, inputs)[0]


def rotation_starts(inputs: ChainInputs, mode: Mode) -> tuple[tuple[float, ...], ...]:
    """Multi-start points for the rotation fit: none, the mount's rotation dropped, all rotation dropped."""
    starts: list[tuple[float, ...]] = []
    mount = inputs.mount
    if mount is not None and mode == "as_run":
        starts.append(tuple(float(v) for v in quat_to_rotvec(quat_conjugate(mount.q_parent_link))))
    q_link_cam = mount.q_link_cam if mount is not None else np.array([0.0, 0.0, 0.0, 1.0])
    # R_bc exp(R_cam_link x) = I  ->  x = R_link_cam rotvec(R_bc^-1)
    lost_all = quat_rotate(q_link_cam, quat_to_rotvec(quat_conjugate(inputs.q_bc[0])))
    starts.append(tuple(float(v) for v in (lost_all if mode == "as_run" else -lost_all)))
    return tuple(starts)
