"""What a rig's cameras can tell about each other: which cameras are compared (groups), which one sets the
gauge of each group, what is not observable, and the comparisons to draw.

Cameras are linked when they saw one label at the same instant, or (with a pose) one static object in
one window; the connected groups of that graph are checked separately. Without a moving pose (a fixed
rig, or no pose at all) nothing fixes a group's orientation or clock: its first camera in the chain's
order sets the gauge in a group of two (the other carries any fault found between them, which could
equally be the first's), and in a larger group the majority does (the one camera whose fault explains
the others' disagreement). How one group sits relative to another cannot be checked at all. With a
moving pose every camera is checked against the world, alone or with the others.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np

from framechain.arrays import FloatArray, IntArray


class RigPose(StrEnum):
    """How the rig's body is placed in the world."""

    MOVING = "moving"  # a recorded pose that moves (odometry, /tf)
    FIXED = "fixed"  # the body is the world, or its pose never changes
    NONE = "none"  # no pose: only sightings at the same instant are compared, in the body frame


@dataclass(frozen=True)
class CameraGroup:
    """Cameras compared with each other (indices into the rig's cameras), and the one that sets the gauge
    (None: the pose does, or the group is too small to say anything)."""

    cameras: tuple[int, ...]
    gauge: int | None


@dataclass(frozen=True)
class PairLines:
    """The same-instant comparisons as recorded, to draw: each compared observation (``obs_id``) with the other
    camera's point at its instant (in the comparison frame) and that camera's frame."""

    obs_id: IntArray
    partner_frame: tuple[str, ...]
    partner_point: FloatArray  # (M, 3)

    def __len__(self) -> int:
        return int(self.obs_id.shape[0])


@dataclass(frozen=True)
class RigLayout:
    """The rig as the evidence sees it."""

    frames: tuple[str, ...]  # every camera's optical frame, in the chain's order
    pose: RigPose
    observations: tuple[int, ...]  # replayed observations per camera
    compared: tuple[int, ...]  # observations per camera compared with another camera's
    links: dict[tuple[int, int], int]  # (a, b), a < b -> comparisons between the two
    groups: tuple[CameraGroup, ...]
    lines: PairLines | None = field(default=None, compare=False)

    def group_of(self, camera: int) -> CameraGroup:
        return next(g for g in self.groups if camera in g.cameras)

    def checkable(self, camera: int) -> bool:
        """Whether a fault of this camera can be found (not the gauge of a group of two, not alone without a
        moving pose)."""
        group = self.group_of(camera)
        if self.pose is RigPose.MOVING:
            return True
        if len(group.cameras) < 2:
            return False
        return len(group.cameras) > 2 or camera != group.gauge

    def gauge_note(self, camera: int) -> str:
        """For a finding on ``camera``: which camera it was measured against when that one could be off too."""
        group = self.group_of(camera)
        if self.pose is RigPose.MOVING or len(group.cameras) != 2 or group.gauge is None:
            return ""
        other = self.frames[group.gauge]
        return (f" ({self.frames[camera]} is compared with {other} only: {other} sets the gauge, so the fault may "
                f"be {other}'s instead; check it against a third camera or a known target)")

    def notes(self) -> list[str]:
        """What the rig's evidence compares, and what it cannot see."""
        out = [self._compared_text()]
        out.extend(self.unobservable())
        return out

    def _compared_text(self) -> str:
        parts = []
        for (a, b), n in sorted(self.links.items()):
            parts.append(f"{self.frames[a]} with {self.frames[b]} {n}")
        how = {RigPose.MOVING: "in the world (the rig's pose moves)", RigPose.FIXED: "in the world (a fixed rig)",
               RigPose.NONE: "in the rig's frame at the same instant (no pose)"}[self.pose]
        listed = "; ".join(parts) if parts else "none"
        return f"rig: {len(self.frames)} cameras compared {how}; comparisons: {listed}"

    def unobservable(self) -> list[str]:
        """One sentence per thing the rig's evidence cannot check."""
        out: list[str] = []
        alone = [self.frames[g.cameras[0]] for g in self.groups if len(g.cameras) == 1]
        if self.pose is not RigPose.MOVING and alone:
            out.append(f"not observable: the chain of {', '.join(alone)} (no other camera saw what "
                       f"{'it' if len(alone) == 1 else 'they'} saw at the same instant or place)")
        linked = [g for g in self.groups if len(g.cameras) > 1]
        if self.pose is not RigPose.MOVING and len(linked) > 1:
            names = [f"{{{', '.join(self.frames[c] for c in g.cameras)}}}" for g in linked]
            out.append(f"not observable: the pose and clock of {' relative to '.join(names)} (no camera of one "
                       "group saw what a camera of another saw; each group is checked on its own)")
        for g in linked:
            if self.pose is not RigPose.MOVING and len(g.cameras) == 2 and g.gauge is not None:
                other = next(c for c in g.cameras if c != g.gauge)
                out.append(f"gauge: {self.frames[g.gauge]} sets the gauge of {{{self.frames[g.gauge]}, "
                           f"{self.frames[other]}}}: a fault between them is reported on {self.frames[other]}")
        return out

    def to_json(self) -> dict[str, Any]:
        group_index = {c: i for i, g in enumerate(self.groups) for c in g.cameras}
        return {
            "pose": self.pose.value,
            "cameras": [{"frame": f, "observations": self.observations[k], "compared": self.compared[k],
                         "group": group_index.get(k), "gauge": any(g.gauge == k for g in self.groups)}
                        for k, f in enumerate(self.frames)],
            "comparisons": [{"cameras": [self.frames[a], self.frames[b]], "count": n}
                            for (a, b), n in sorted(self.links.items())],
            "groups": [[self.frames[c] for c in g.cameras] for g in self.groups],
            "unobservable": self.unobservable(),
        }


def camera_groups(n_cameras: int, links: dict[tuple[int, int], int], pose: RigPose) -> tuple[CameraGroup, ...]:
    """Connected groups of cameras (in the chain's order), each with its gauge camera."""
    parent = list(range(n_cameras))

    def root(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for (a, b), n in links.items():
        if n > 0:
            ra, rb = root(a), root(b)
            parent[max(ra, rb)] = min(ra, rb)
    members: dict[int, list[int]] = {}
    for c in range(n_cameras):
        members.setdefault(root(c), []).append(c)
    groups = []
    for cams in members.values():
        gauge = None if pose is RigPose.MOVING or len(cams) < 2 else cams[0]
        groups.append(CameraGroup(tuple(cams), gauge))
    return tuple(sorted(groups, key=lambda g: g.cameras[0]))


def count_links(camera_a: IntArray, camera_b: IntArray) -> dict[tuple[int, int], int]:
    """Comparisons per unordered pair of cameras."""
    lo, hi = np.minimum(camera_a, camera_b), np.maximum(camera_a, camera_b)
    keep = lo != hi
    pairs, counts = np.unique(np.stack([lo[keep], hi[keep]], axis=1), axis=0, return_counts=True) \
        if keep.any() else (np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64))
    return {(int(a), int(b)): int(n) for (a, b), n in zip(pairs.tolist(), counts.tolist(), strict=True)}


__all__ = ["CameraGroup", "PairLines", "RigLayout", "RigPose", "camera_groups", "count_links"]
