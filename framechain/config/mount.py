"""A mount: a frame held on its parent at all times (a camera on the link it is screwed to, a fixed joint of a
URDF, a static edge a chain declares), and the two ways a file declares one.

A chain's ``mounts:`` entry names both frames::

    mounts:
      - {parent: base_link, child: camera_link, xyz: [0.3, 0, 0.8], rpy: [0, 0.1, 0]}  # or quat_xyzw, rotvec

A camera calibration's ``mount:`` names the parent; the child is the camera's optical frame
(``optical: true``) or its camera_link (``optical: false``, with the REP-103 rotation to the optical
frame below it)::

    mount: {parent: gripper_link, xyz: [0.0, -0.03, 0.02], rpy: [0.0, 0.0, 0.0], optical: false}
"""

from __future__ import annotations

from dataclasses import dataclass, field

from framechain.config.schema import ROTATION_KEYS, Section, as_list

__all__ = ["CAMERA_MOUNT_KEYS", "Mount", "camera_mount", "chain_mounts"]


@dataclass(frozen=True)
class Mount:
    """``T_parent_child`` at all times: translation ``xyz`` (m) and rotation ``quat_xyzw``.

    ``optical``: whether the child is a camera's optical frame (x right, y down, z forward); False for a
    camera_link (x forward, y left, z up) with the REP-103 rotation to the optical frame below it; None
    for a mount that is no camera's (a fixed joint, a chain's static edge). ``source`` says where it was
    declared; ``form`` is the rotation key the file gave (``quat_xyzw``, ``rpy`` or ``rotvec``): a fix
    writes the mount back in it.
    """

    parent: str
    child: str
    xyz: tuple[float, float, float]
    quat_xyzw: tuple[float, float, float, float]
    optical: bool | None = None
    source: str = field(default="", compare=False)
    form: str = field(default="quat_xyzw", compare=False)


_CHAIN_MOUNT_KEYS = {"parent", "child", "xyz", *ROTATION_KEYS}
_CHAIN_MOUNT_WHAT = "{parent, child, xyz, quat_xyzw | rpy | rotvec}"


def chain_mounts(top: Section) -> tuple[Mount, ...]:
    """A chain's ``mounts:``, one entry or a list, each ``T_parent_child``."""
    return tuple(_chain_mount(top.child(m, f"mounts[{i}]", _CHAIN_MOUNT_KEYS, what=_CHAIN_MOUNT_WHAT))
                 for i, m in enumerate(as_list(top.get("mounts"))))


def _chain_mount(mount: Section) -> Mount:
    """``{parent, child, xyz, quat_xyzw | rpy | rotvec}`` as ``T_parent_child``."""
    parent = mount.frame("parent", required=True, hint="a frame name") or ""
    child = mount.frame("child", required=True, hint="a frame name") or ""
    if parent == child:
        mount.fail(f"parent and child are the same frame {parent!r}")
    pose = mount.pose(rotation_required=True)
    form = next(k for k in ROTATION_KEYS if k in mount)
    return Mount(parent, child, pose.xyz, pose.quat_xyzw, form=form)


#: The keys of a camera calibration's ``mount:``.
CAMERA_MOUNT_KEYS = {"parent", "xyz", *ROTATION_KEYS, "optical"}


def camera_mount(section: Section) -> Mount:
    """A camera calibration's ``mount:``, ``{parent, xyz, rpy | quat_xyzw | rotvec, optical}``; its child, the
    camera's optical frame or (``optical: false``) its camera_link, is left to the calibration that names them
    (:func:`framechain.config.calibration.load_calibration`)."""
    parent = section.frame("parent", required=True, hint="the link the camera is mounted on")
    if not isinstance(section.get("optical"), bool):
        section.fail_at(
            section.path("optical"),
            "must be stated, true or false: true if the mount gives the optical frame (x right, y down, z "
            "forward), false if it gives a camera_link (x forward, y left, z up)",
        )
    pose = section.pose(rotation_required=False)
    optical = bool(section.get("optical"))
    form = next((k for k in ROTATION_KEYS if k in section), "quat_xyzw")
    return Mount(parent or "", "", pose.xyz, pose.quat_xyzw, optical, f"{section.source} {section.where}", form)
