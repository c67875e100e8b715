"""robot.yaml bound to the URDF's model: the joints it maps exist and move, the cameras hang below
driven joints, and the dataset's joint values become joint positions in SI units.

Reading and checking the file itself is :mod:`framechain.config.robot`'s job.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray
from framechain.config.errors import RobotConfigError
from framechain.config.robot import ArmConfig, JointMapping, JointUnit, RobotConfig
from framechain.geometry.rotations import homogeneous
from framechain.robot.kinematics import RobotModel
from framechain.robot.urdf import Joint, JointType, Mimic

__all__ = ["arm_root", "check_robot", "convert_joint", "joint_positions", "out_of_limits", "robot_model",
           "unit_mismatches"]


def robot_model(config: RobotConfig) -> RobotModel:
    """The URDF's kinematic model (several arms: one tree under the world frame, each arm's frames and
    joints prefixed, its base placed by a fixed joint), checked against the joint mapping and the mounts."""
    if not config.arms:
        model = RobotModel.from_urdf(config.urdf)
    else:
        joints: list[Joint] = []
        parsed: dict[str, RobotModel] = {}  # two arms of one kind share their URDF: parsed once
        for arm in config.arms:
            if str(arm.urdf) not in parsed:
                parsed[str(arm.urdf)] = RobotModel.from_urdf(arm.urdf)
            joints.extend(_arm_joints(config.arms_frame, arm, parsed[str(arm.urdf)]))
        model = RobotModel(joints, source=config.source, name="+".join(a.name for a in config.arms))
    check_robot(config, model)
    return model


def arm_root(config: RobotConfig, model: RobotModel, link: str | None = None) -> str:
    """The root link of the arm ``link`` belongs to (the first arm's by default; the model's root for one URDF)."""
    if not config.arms:
        return model.root
    arms = [a for a in config.arms if link is not None and link.startswith(a.prefix)] or [config.arms[0]]
    return next(j.child for j in model.joints.values() if j.name == _base_joint(config.arms_frame, arms[0]))


def _base_joint(world: str, arm: ArmConfig) -> str:
    return f"{world}_to_{arm.prefix}base"


def _arm_joints(world: str, arm: ArmConfig, model: RobotModel) -> list[Joint]:
    """One arm's joints, names prefixed, below a fixed joint from the world frame to its root."""
    p = arm.prefix
    origin = homogeneous(np.asarray(arm.world_from_base_quat_xyzw, dtype=float),
                         np.asarray(arm.world_from_base_translation, dtype=float), n=1)[0]
    out = [Joint(name=_base_joint(world, arm), type=JointType.FIXED, parent=world, child=p + model.root,
                 origin=origin, axis=np.array([0.0, 0.0, 1.0]))]
    for j in model.joints.values():
        mimic = None if j.mimic is None else Mimic(p + j.mimic.joint, j.mimic.multiplier, j.mimic.offset)
        out.append(Joint(name=p + j.name, type=j.type, parent=p + j.parent, child=p + j.child, origin=j.origin,
                         axis=j.axis, lower=j.lower, upper=j.upper, mimic=mimic))
    return out


def convert_joint(mapping: JointMapping, values: npt.ArrayLike, lower: float | None, upper: float | None
                  ) -> FloatArray:
    """Dataset values of one state -> the joint's position in SI (radians or metres)."""
    x = np.asarray(values, dtype=float)
    if mapping.unit in (JointUnit.RAD, JointUnit.M):
        si = x
    elif mapping.unit is JointUnit.DEG:
        si = np.deg2rad(x)
    elif mapping.unit is JointUnit.MM:
        si = x * 1e-3
    elif mapping.unit is JointUnit.TICKS:
        si = _ticks_angle(mapping, x)
    else:
        frac = x / 100.0 if mapping.unit is JointUnit.RANGE_0_100 else (x + 100.0) / 200.0
        if mapping.ticks_range is not None:  # LeRobot's normalisation of a calibrated range, read back to ticks
            lo, hi = mapping.ticks_range
            si = _ticks_angle(mapping, lo + (1.0 - frac if mapping.inverted else frac) * (hi - lo))
        elif lower is None or upper is None:
            raise RobotConfigError(
                mapping.state, f"unit {mapping.unit.value} needs joint limits, and joint {mapping.joint!r} has none"
            )
        else:
            si = lower + frac * (upper - lower)
    out: FloatArray = mapping.sign * si + mapping.offset
    return out


def _ticks_angle(mapping: JointMapping, ticks: FloatArray) -> FloatArray:
    out: FloatArray = (ticks - mapping.zero_ticks) * (2.0 * np.pi / mapping.ticks_per_turn)
    return out


def joint_positions(config: RobotConfig, model: RobotModel, values: npt.ArrayLike, names: Sequence[str]
                    ) -> dict[str, FloatArray]:
    """``(T, n)`` dataset state vectors with column ``names`` -> ``{joint: (T,)}`` in SI units."""
    arr = np.asarray(values, dtype=float)
    config.check_names(names)
    index = {n: i for i, n in enumerate(names)}
    out: dict[str, FloatArray] = {}
    for m in config.joints:
        lower, upper = model.limits(m.joint)
        out[m.joint] = convert_joint(m, arr[:, index[m.state]], lower, upper)
    return out


def check_robot(config: RobotConfig, model: RobotModel) -> None:
    """Every mapped or held joint exists and moves; every camera path is fully driven."""
    fail = config.source
    for m in config.joints:
        joint = model.joints.get(m.joint)
        if joint is None:
            raise RobotConfigError(fail, f"joints.{m.state}: the URDF has no joint {m.joint!r}; its moving joints are "
                                   f"{list(model.actuated)}")
        if not joint.moves or joint.mimic is not None:
            raise RobotConfigError(fail, f"joints.{m.state}: joint {m.joint!r} is fixed or a mimic joint")
        if (m.unit is JointUnit.TICKS or m.ticks_range is not None) and joint.type is JointType.PRISMATIC:
            how = "unit ticks" if m.unit is JointUnit.TICKS else f"unit {m.unit.value} with a calibration JSON"
            raise RobotConfigError(fail, f"joints.{m.state}: {how} turns a revolute joint; {m.joint!r} slides")
        if (m.unit in (JointUnit.RANGE_0_100, JointUnit.RANGE_M100_100) and m.ticks_range is None
                and (joint.lower is None or joint.upper is None)):
            raise RobotConfigError(fail, f"joints.{m.state}: unit {m.unit.value} needs limits on joint {m.joint!r}, "
                                   "which has none")
    for name in config.hold:
        if name not in model.actuated:
            raise RobotConfigError(fail, f"hold.{name}: not a moving, non-mimic URDF joint")
    if config.mobile_base is not None and model.has_link(config.arms_frame):
        raise RobotConfigError(fail, f"mobile_base.frame {config.arms_frame!r} is a link of the URDF already; name the "
                               "base's frame another way")
    driven = {m.joint for m in config.joints} | set(config.hold)
    for cam in config.cameras.values():
        # A camera named "wrist" on an SO-101 would add a second parent to the URDF's wrist_link.
        frames = [cam.optical_frame] if cam.mount.optical else [cam.link_frame, cam.optical_frame]
        taken = [f for f in frames if model.has_link(f) or f in (config.world_frame, config.arms_frame)]
        if taken:
            raise RobotConfigError(fail, f"camera {cam.name!r}: its frame {taken[0]!r} is already a link of the URDF; "
                                   f"give the camera another name (e.g. {cam.name}_cam)")
        parent = cam.mount.parent
        if parent in (config.world_frame, config.arms_frame):
            continue
        if not model.has_link(parent):
            base = f" nor the mobile base's frame {config.arms_frame!r}" if config.mobile_base is not None else ""
            raise RobotConfigError(fail, f"camera {cam.name!r} is mounted on {parent!r}, which is neither a URDF link "
                                   f"nor the world frame {config.world_frame!r}{base}")
        free = [j.name for j in model.path_joints(parent) if j.moves and j.mimic is None and j.name not in driven]
        if free:
            raise RobotConfigError(fail, f"camera {cam.name!r} hangs below joints {free} that no dataset state drives: "
                                   "map them under joints or fix them under hold")
    body = config.chain_body
    if body is not None and body not in (config.world_frame, config.arms_frame) and not model.has_link(body):
        raise RobotConfigError(fail, f"chain.body {body!r} is not a URDF link")


def unit_mismatches(config: RobotConfig, values: npt.ArrayLike, names: Sequence[str]) -> list[str]:
    """A note naming the mapped states whose recorded values their declared unit cannot hold: servo ticks below 0,
    above a turn or mostly fractional, or a percentage beyond 100 (degrees declared as ticks read as a joint
    held near -180 deg that barely moves, within its limits)."""
    arr = np.asarray(values, dtype=float)
    index = {n: i for i, n in enumerate(names)}
    odd = []
    for m in config.joints:
        column = arr[:, index[m.state]]
        why = _impossible_in(m, column[np.isfinite(column)])
        if why:
            odd.append(f"{m.state} ({m.unit.value}) holds {why}")
    if not odd:
        return []
    return [f"{config.source}: the state holds values its declared unit cannot: {'; '.join(odd)}: is the unit right "
            "(joints.NAME.unit, default_unit)?"]


def _impossible_in(mapping: JointMapping, values: FloatArray) -> str:
    """Why ``values`` were not recorded in the mapping's unit ("" when they may have been)."""
    unit, turn = mapping.unit, mapping.ticks_per_turn
    if not values.size:
        return ""
    lo, hi = float(values.min()), float(values.max())
    seen = f"{lo:.4g}..{hi:.4g}"
    if unit is JointUnit.TICKS:
        fractional = float(np.mean(np.abs(values - np.round(values)) > 1e-6))
        if lo < 0.0 or hi > turn:
            return f"{seen}, outside a servo's 0..{turn:.0f} counts"
        if fractional > 0.5:
            return f"{seen}, {fractional:.0%} of them fractional where servo counts are whole"
    if unit is JointUnit.RANGE_M100_100 and (lo < -100.5 or hi > 100.5):
        return f"{seen}, beyond -100..100"
    if unit is JointUnit.RANGE_0_100 and (lo < -0.5 or hi > 100.5):
        return f"{seen}, beyond 0..100"
    return ""


def out_of_limits(config: RobotConfig, model: RobotModel, positions: dict[str, FloatArray]) -> list[str]:
    """A note naming the mapped revolute joints the state puts far outside their URDF limits (by more than half their
    range and 0.5 rad): a unit read wrongly (degrees read as radians reach tens of radians) or another robot's URDF."""
    far = []
    for m in config.joints:
        lower, upper = model.limits(m.joint)
        joint = model.joints[m.joint]
        values = positions[m.joint]
        if joint.type is not JointType.REVOLUTE or lower is None or upper is None or not values.size:
            continue
        margin = max(0.5 * (upper - lower), 0.5)
        low, high = float(np.nanmin(values)), float(np.nanmax(values))
        if low < lower - margin or high > upper + margin:
            far.append(f"{m.state} ({m.unit.value}) puts {m.joint} at {low:.2f}..{high:.2f} rad, its limits "
                       f"{lower:.2f}..{upper:.2f}")
    if not far:
        return []
    return [f"{config.source}: the state puts joints far outside their URDF limits: {'; '.join(far)}: is the unit "
            "right (joints.NAME.unit, default_unit), and the URDF this robot's?"]
