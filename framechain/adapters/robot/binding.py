"""robot.yaml bound to the URDF's model: the joints it maps exist and move, the cameras hang below
driven joints, and the dataset's joint values become joint positions in SI units.

Reading and checking the file itself is :mod:`framechain.config.robot`'s job.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from framechain.adapters.robot.kinematics import RobotModel
from framechain.arrays import FloatArray
from framechain.config.errors import RobotConfigError
from framechain.config.robot import JointMapping, JointUnit, RobotConfig

__all__ = ["check_robot", "convert_joint", "joint_positions", "robot_model"]


def robot_model(config: RobotConfig) -> RobotModel:
    """The URDF's kinematic model, checked against the joint mapping and the camera mounts."""
    model = RobotModel.from_urdf(config.urdf)
    check_robot(config, model)
    return model


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
    else:
        if lower is None or upper is None:
            raise RobotConfigError(
                mapping.state, f"unit {mapping.unit.value} needs joint limits, and joint {mapping.joint!r} has none"
            )
        frac = x / 100.0 if mapping.unit is JointUnit.RANGE_0_100 else (x + 100.0) / 200.0
        si = lower + frac * (upper - lower)
    out: FloatArray = mapping.sign * si + mapping.offset
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
        if m.unit in (JointUnit.RANGE_0_100, JointUnit.RANGE_M100_100) and (joint.lower is None or joint.upper is None):
            raise RobotConfigError(fail, f"joints.{m.state}: unit {m.unit.value} needs limits on joint {m.joint!r}, "
                                   "which has none")
    for name in config.hold:
        if name not in model.actuated:
            raise RobotConfigError(fail, f"hold.{name}: not a moving, non-mimic URDF joint")
    driven = {m.joint for m in config.joints} | set(config.hold)
    for cam in config.cameras.values():
        # A camera named "wrist" on an SO-101 would add a second parent to the URDF's wrist_link.
        frames = [cam.optical_frame] if cam.mount.optical else [cam.link_frame, cam.optical_frame]
        taken = [f for f in frames if model.has_link(f) or f == config.world_frame]
        if taken:
            raise RobotConfigError(fail, f"camera {cam.name!r}: its frame {taken[0]!r} is already a link of the URDF; "
                                   f"give the camera another name (e.g. {cam.name}_cam)")
        parent = cam.mount.parent
        if parent == config.world_frame:
            continue
        if not model.has_link(parent):
            raise RobotConfigError(fail, f"camera {cam.name!r} is mounted on {parent!r}, which is neither a URDF link "
                                   f"nor the world frame {config.world_frame!r}")
        free = [j.name for j in model.path_joints(parent) if j.moves and j.mimic is None and j.name not in driven]
        if free:
            raise RobotConfigError(fail, f"camera {cam.name!r} hangs below joints {free} that no dataset state drives: "
                                   "map them under joints or fix them under hold")
    body = config.chain_body
    if body is not None and body != config.world_frame and not model.has_link(body):
        raise RobotConfigError(fail, f"chain.body {body!r} is not a URDF link")
