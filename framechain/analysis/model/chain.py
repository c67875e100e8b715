"""The chain as a function of its faults: recompute every hop under a perturbation, vectorised.

A :class:`Perturbation` says how the chain that produced some points differs from the recorded
one: intrinsics scaled, depth scaled, the camera-to-body rotation changed, replaced or permuted,
a transform inverted, the pose looked up at another time or in another world frame. Fault
models (``faults.py``) are small functions from parameters to a Perturbation; fitting them is
evaluating :func:`evaluate` many times on whole arrays of observations.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray, IntArray
from framechain.config.chain import ChainFrames
from framechain.config.mount import Mount
from framechain.geometry.camera import CameraModel
from framechain.geometry.conventions import OPTICAL_FROM_LINK_QUAT_XYZW
from framechain.geometry.rotations import (
    quat_angle_between,
    quat_conjugate,
    quat_from_rotvec,
    quat_multiply,
    quat_rotate,
)
from framechain.geometry.transforms import invert_rows, transform_points
from framechain.replay import Edge, LookupStatus, ReplayResult, TransformBuffer
from framechain.replay.composition import compose_hops

#: Shifted pose lookups :class:`ChainInputs` keeps (a few: each holds N poses).
_SHIFTED_POSES_KEPT = 4


@dataclass(frozen=True)
class CameraDelta:
    """How one camera of a rig differs from the recorded chain (defaults: not at all)."""

    #: its mount's rotation changed, the rotation vector in the mount's link frame (as ``rotvec_mount``)
    rotvec_mount: FloatArray = field(default_factory=lambda: np.zeros(3))
    #: added to the camera's position in the body frame (m)
    translation_m: FloatArray = field(default_factory=lambda: np.zeros(3))
    offset_s: float = 0.0  # its detections were taken at their stamp + offset_s
    focal_scale: float = 1.0  # its fx, fy scaled
    depth_factor: float = 1.0  # its depths scaled


@dataclass(frozen=True)
class Perturbation:
    """How a chain differs from the recorded one (defaults: not at all)."""

    focal_scale: float = 1.0  # fx, fy used = s * fx, fy
    principal_scale: float = 1.0  # cx, cy used = s * cx, cy (another resolution scales both)
    depth_factor: float = 1.0  # depth_used = factor * depth
    #: the camera mount's rotation changed: R_parent_link' = R_parent_link exp(rotvec_mount), the rotation
    #: vector in the mount's link frame (constant for a camera on a moving arm)
    rotvec_mount: FloatArray = field(default_factory=lambda: np.zeros(3))
    #: the camera mount's position changed: t_parent_link' = t_parent_link + translation_mount (m, in the mount's
    #: parent frame; the body frame without a static mount), constant for a camera on a moving arm
    translation_mount: FloatArray = field(default_factory=lambda: np.zeros(3))
    permutation: FloatArray | None = None  # R_bc' = R_bc P: camera-frame axes permuted / flipped
    invert_camera: bool = False  # T_bc' = inv(T_bc)
    invert_edge: str | None = None  # one recorded edge of the camera path (named by child) inverted
    camera_offset_s: float = 0.0  # camera_to_body looked up at tau + offset (a moving camera)
    pose_offset_s: float = 0.0  # body_to_world looked up at tau + offset
    invert_pose: bool = False  # T_wb' = inv(T_wb)
    world: str | None = None  # another world frame (odom for map)
    #: camera_to_body looked up from this frame instead of the chain's camera frame (camera_link for
    #: camera_color_optical_frame: the whole optical edge, rotation and translation, dropped)
    camera_frame: str | None = None
    #: body_to_world looked up for this frame instead of the chain's body (base_footprint for base_link)
    body_frame: str | None = None
    #: per camera of a rig (the index into ``ChainInputs.rig_cameras``): how that camera differs
    cameras: Mapping[int, CameraDelta] = field(default_factory=dict)

    def with_camera(self, index: int, **changes: Any) -> Perturbation:
        """This perturbation with rig camera ``index``'s :class:`CameraDelta` changed as ``changes`` say."""
        delta = replace(self.cameras.get(index, CameraDelta()), **changes)
        return replace(self, cameras={**self.cameras, index: delta})


@dataclass(frozen=True)
class CameraMount:
    """A camera's mount as the replayed frame graph holds it: the static edge it hangs from (``edge``,
    parent -> link, as recorded) and the rotation from that link to the camera below it.

    For a ROS camera, ``base_link -> camera_link`` with the REP-103 optical rotation below it; for
    a wrist camera, ``flange -> wrist_link``; for a camera frame published directly, the camera's
    own edge (``link`` is then the camera frame, ``edge.optical`` True, and ``q_link_cam`` the identity).
    """

    edge: Mount
    q_link_cam: FloatArray

    @property
    def parent(self) -> str:
        return self.edge.parent

    @property
    def link(self) -> str:
        return self.edge.child

    @property
    def t_parent_link(self) -> FloatArray:
        return np.asarray(self.edge.xyz)

    @property
    def q_parent_link(self) -> FloatArray:
        return np.asarray(self.edge.quat_xyzw)


def find_mount(buffer: TransformBuffer, body: str, camera: str) -> CameraMount | None:
    """The camera's mount on the path from ``camera`` up to ``body`` (None when there is no static one)."""
    path = buffer.path(body, camera)
    if not path.connected or not path.hops or path.hops[0].inverse:
        return None
    edges = buffer.edges
    first = edges[path.hops[0].child]
    if not first.is_static:
        return None
    off_optical = quat_angle_between(np.asarray(OPTICAL_FROM_LINK_QUAT_XYZW), first.quat_xyzw[0])
    if len(path.hops) > 1 and not path.hops[1].inverse and np.rad2deg(off_optical) < 1.0:
        mount = edges[path.hops[1].child]
        if mount.is_static:
            return CameraMount(_recorded(mount, optical=False), first.quat_xyzw[0].copy())
    return CameraMount(_recorded(first, optical=True), np.array([0.0, 0.0, 0.0, 1.0]))


def _recorded(edge: Edge, *, optical: bool) -> Mount:
    """A static edge of the frame graph as a mount (its one sample)."""
    t, q = edge.translation[0].tolist(), edge.quat_xyzw[0].tolist()
    return Mount(edge.parent, edge.child, (t[0], t[1], t[2]), (q[0], q[1], q[2], q[3]), optical, edge.source)


@dataclass(frozen=True)
class CameraInputs:
    """One rig camera's part of the chain's inputs: its optical frame, camera model and static mount (not the
    camera a chain declares: :class:`framechain.config.chain_cameras.RigCamera`)."""

    frame: str
    camera: CameraModel
    mount: CameraMount | None


@dataclass(frozen=True)
class ChainInputs:
    """The replayed observations with everything a perturbed recomputation needs.

    A rig's inputs hold every camera (``rig_cameras``) and each observation's camera (``camera_index``);
    ``camera`` and ``frames.camera`` are then the first camera's.
    """

    obs_id: IntArray
    stamp_ns: IntArray
    u: FloatArray
    v: FloatArray
    depth_m: FloatArray
    camera: CameraModel
    t_bc: FloatArray  # (N, 3) recorded T_body_cam at tau
    q_bc: FloatArray  # (N, 4)
    t_wb: FloatArray  # (N, 3) recorded T_world_body at tau
    q_wb: FloatArray
    buffer: TransformBuffer
    frames: ChainFrames
    camera_is_dynamic: bool
    #: A resample's source and its rows there (see :meth:`take`); None for inputs taken from a replay.
    resampled_from: tuple[ChainInputs, IntArray] | None = field(default=None, compare=False, repr=False)
    rig_cameras: tuple[CameraInputs, ...] = ()
    camera_index: IntArray | None = None  # (N,) index into rig_cameras (None: one camera)

    def __len__(self) -> int:
        return int(self.stamp_ns.shape[0])

    @classmethod
    def from_rig_replay(cls, result: ReplayResult, buffer: TransformBuffer,
                        models: Mapping[str, CameraModel]) -> ChainInputs:
        """The inputs of a rig's replay: ``models`` gives each camera frame's model, in the rig's order
        (the first is the chain's camera)."""
        frames = list(models)
        cameras = tuple(CameraInputs(f, models[f], find_mount(buffer, result.frames.body, f)) for f in frames)
        base = cls.from_replay(result, buffer, models[frames[0]])
        observed = result.observations.camera_frame[result.replayed]
        index = np.full(observed.shape[0], -1, dtype=np.int64)
        for k, f in enumerate(frames):
            index[observed == f] = k
        dynamic = any(not h.is_static for f in frames for h in buffer.path(result.frames.body, f).hops)
        return replace(base, rig_cameras=cameras, camera_index=index, camera_is_dynamic=dynamic)

    @classmethod
    def from_replay(cls, result: ReplayResult, buffer: TransformBuffer, camera: CameraModel) -> ChainInputs:
        ok = result.replayed
        path = buffer.path(result.frames.body, result.frames.camera)
        return cls(
            obs_id=result.observations.obs_id[ok],
            stamp_ns=result.observations.stamp_ns[ok],
            u=result.observations.u[ok],
            v=result.observations.v[ok],
            depth_m=result.depth_m[ok],
            camera=camera,
            t_bc=result.body_from_cam.translation[ok],
            q_bc=result.body_from_cam.quat_xyzw[ok],
            t_wb=result.world_from_body.translation[ok],
            q_wb=result.world_from_body.quat_xyzw[ok],
            buffer=buffer,
            frames=result.frames,
            camera_is_dynamic=any(not h.is_static for h in path.hops),
        )

    def take(self, index: npt.ArrayLike) -> ChainInputs:
        """A subset of observations (bootstrap resamples).

        A resample as large as its source looks its shifted poses up through the source: the rows'
        poses are the same, and every resample of a bootstrap asks for the same few offsets.
        """
        i = np.asarray(index)
        source: tuple[ChainInputs, IntArray] | None = None
        if i.dtype.kind in "iu" and i.ndim == 1 and i.shape[0] >= len(self):
            source = (self, i) if self.resampled_from is None else \
                (self.resampled_from[0], self.resampled_from[1][i])
        return replace(
            self,
            resampled_from=source,
            obs_id=self.obs_id[i],
            stamp_ns=self.stamp_ns[i],
            u=self.u[i],
            v=self.v[i],
            depth_m=self.depth_m[i],
            t_bc=self.t_bc[i],
            q_bc=self.q_bc[i],
            t_wb=self.t_wb[i],
            q_wb=self.q_wb[i],
            camera_index=None if self.camera_index is None else self.camera_index[i],
        )

    @cached_property
    def ray(self) -> FloatArray:
        """Undistorted rays [x, y, 1] through the recorded intrinsics."""
        return self.rays_scaled(1.0, {})

    def rays_scaled(self, focal_scale: float, camera_scales: Mapping[int, float], principal_scale: float = 1.0
                    ) -> FloatArray:
        """Rays through intrinsics whose focal lengths are scaled (``camera_scales``: per rig camera, on top)."""
        if self.camera_index is None:
            return _rays(self.camera, self.u, self.v, focal_scale, principal_scale)
        out = np.full((len(self), 3), np.nan)
        for k, cam in enumerate(self.rig_cameras):
            rows = self.camera_index == k
            if rows.any():
                out[rows] = _rays(cam.camera, self.u[rows], self.v[rows], focal_scale * camera_scales.get(k, 1.0),
                                  principal_scale)
        return out

    def per_camera(self, values: Mapping[int, float], default: float) -> FloatArray:
        """A value per observation from a value per rig camera (``default`` for the others)."""
        out = np.full(len(self), default)
        if self.camera_index is not None:
            for k, value in values.items():
                out[self.camera_index == k] = value
        return out

    @cached_property
    def mount(self) -> CameraMount | None:
        """The camera's static mount, where mount rotation errors are expressed and fixed."""
        return find_mount(self.buffer, self.frames.body, self.frames.camera)

    def world_from_body(
        self, offset_s: float, world: str | None, body: str | None = None
    ) -> tuple[FloatArray, FloatArray, npt.NDArray[np.bool_]]:
        """T_world_body at tau + offset in ``world`` for ``body`` (defaults: the chain's), and which
        times were usable."""
        same_frames = (world is None or world == self.frames.world) and (body is None or body == self.frames.body)
        if offset_s == 0.0 and same_frames:
            return self.t_wb, self.q_wb, np.ones(len(self), dtype=bool)
        key = (round(offset_s * 1e9), world or self.frames.world, body or self.frames.body)
        poses = self._shifted_poses.get(key)
        if poses is None:
            if self.resampled_from is not None:
                source, rows = self.resampled_from
                t, q, ok = source.world_from_body(offset_s, world, body)
                poses = (t[rows], q[rows], ok[rows])
            else:
                lookup = self.buffer.lookup(key[1], key[2], self.stamp_ns + key[0])
                poses = (lookup.translation, lookup.quat_xyzw, lookup.ok)
            for array in poses:
                array.setflags(write=False)  # shared by every later call with the same key
            if len(self._shifted_poses) >= _SHIFTED_POSES_KEPT:
                del self._shifted_poses[next(iter(self._shifted_poses))]
            self._shifted_poses[key] = poses
        return poses

    def world_from_body_rows(
        self, offset_s: float, camera_offsets_s: Mapping[int, float], world: str | None, body: str | None = None
    ) -> tuple[FloatArray, FloatArray, npt.NDArray[np.bool_]]:
        """T_world_body at tau + offset + the row's rig camera's own offset (see :meth:`world_from_body`)."""
        shifts = {k: round((offset_s + v) * 1e9) for k, v in sorted(camera_offsets_s.items())}
        key = (round(offset_s * 1e9), tuple(shifts.items()), world or self.frames.world, body or self.frames.body)
        poses = self._shifted_poses.get(key)
        if poses is None:
            times = self.stamp_ns + key[0]
            if self.camera_index is not None:
                for k, shift in shifts.items():
                    times = np.where(self.camera_index == k, self.stamp_ns + shift, times)
            lookup = self.buffer.lookup(key[2], key[3], times)
            poses = (lookup.translation, lookup.quat_xyzw, lookup.ok)
            for array in poses:
                array.setflags(write=False)
            if len(self._shifted_poses) >= _SHIFTED_POSES_KEPT:
                del self._shifted_poses[next(iter(self._shifted_poses))]
            self._shifted_poses[key] = poses
        return poses

    @cached_property
    def _shifted_poses(self) -> dict[Any, tuple[FloatArray, FloatArray, npt.NDArray[np.bool_]]]:
        """Poses looked up by (offset ns, world, body), oldest first: while further faults are fitted on
        top of a latency found before, every evaluation asks for the same shifted pose."""
        return {}

    def body_from_camera(
        self, offset_s: float, invert_edge: str | None = None, camera_frame: str | None = None
    ) -> tuple[FloatArray, FloatArray, npt.NDArray[np.bool_]]:
        """T_body_cam at tau + offset (one edge of its path taken the wrong way round, if named;
        looked up from ``camera_frame`` instead of the chain's camera, if named).

        Also says which observations had a transform at that time (a shifted time can fall outside
        a moving camera's recorded span); those rows are identity and must be masked by the caller.
        """
        ok = np.ones(len(self), dtype=bool)
        source = camera_frame or self.frames.camera
        swapped = source != self.frames.camera
        if invert_edge is not None and not swapped:
            path = self.buffer.path(self.frames.body, self.frames.camera)
            times = self.stamp_ns + round(offset_s * 1e9)
            samples = []
            for hop in path.hops:
                sample = self.buffer.sample(hop, times)
                ok &= sample.status <= LookupStatus.NEAREST
                if hop.child == invert_edge:
                    sample = replace(sample, hop=replace(hop, inverse=not hop.inverse))
                samples.append(sample)
            t, q = compose_hops(tuple(samples), len(self))
            t_bc, q_bc = t.T, q.T
        elif not swapped and (offset_s == 0.0 or not self.camera_is_dynamic):
            return self.t_bc, self.q_bc, ok
        else:
            lookup = self.buffer.lookup(self.frames.body, source, self.stamp_ns + round(offset_s * 1e9))
            t_bc, q_bc, ok = lookup.translation, lookup.quat_xyzw, lookup.ok
        if not ok.all():
            t_bc, q_bc = t_bc.copy(), q_bc.copy()
            t_bc[~ok] = 0.0
            q_bc[~ok] = [0.0, 0.0, 0.0, 1.0]
        return t_bc, q_bc, ok


def _rays(camera: CameraModel, u: FloatArray, v: FloatArray, focal_scale: float, principal_scale: float
          ) -> FloatArray:
    """Undistorted rays [x, y, 1] of pixels through ``camera`` with its K scaled."""
    model = camera
    if focal_scale != 1.0 or principal_scale != 1.0:
        k = camera.K.copy()
        k[:2, :2] *= focal_scale
        k[:2, 2] *= principal_scale
        model = replace(camera, K=k)
    x, y = model.pixel_to_normalized(u, v)
    return np.stack([x, y, np.ones_like(x)], axis=1)


def hop1(inputs: ChainInputs, pert: Perturbation) -> FloatArray:
    """pixel_to_camera under the perturbation: (N, 3) camera-frame points."""
    ray = inputs.ray
    scales = {k: d.focal_scale for k, d in pert.cameras.items() if d.focal_scale != 1.0}
    if pert.focal_scale != 1.0 or pert.principal_scale != 1.0 or scales:
        ray = inputs.rays_scaled(pert.focal_scale, scales, pert.principal_scale)
    depth = inputs.depth_m * pert.depth_factor
    factors = {k: d.depth_factor for k, d in pert.cameras.items() if d.depth_factor != 1.0}
    if factors:
        depth = depth * inputs.per_camera(factors, 1.0)
    return ray * depth[:, None]


def hop2(inputs: ChainInputs, pert: Perturbation, p_cam: FloatArray) -> FloatArray:
    """camera_to_body under the perturbation."""
    t_bc, q_bc, ok = inputs.body_from_camera(pert.camera_offset_s, pert.invert_edge, pert.camera_frame)
    if pert.permutation is not None:
        p_cam = p_cam @ pert.permutation.T
    if np.any(pert.translation_mount):
        shift = np.asarray(pert.translation_mount, dtype=float)[:, None]
        t_bc = t_bc + quat_rotate(body_from_mount_parent(inputs, q_bc).T, shift).T
    if np.any(pert.rotvec_mount):
        # R_bc' = R_bc R_cam_link exp(x) R_link_cam = R_bc exp(R_cam_link x)
        q_link_cam = inputs.mount.q_link_cam if inputs.mount is not None else np.array([0.0, 0.0, 0.0, 1.0])
        rotvec_cam = quat_rotate(quat_conjugate(q_link_cam), np.asarray(pert.rotvec_mount, dtype=float))
        q_bc = quat_multiply(np.asarray(q_bc).T, quat_from_rotvec(rotvec_cam)[:, None]).T
    if pert.cameras and inputs.camera_index is not None:
        t_bc, q_bc = _rig_mounts(inputs, pert, t_bc, q_bc)
    if pert.invert_camera:
        t_bc, q_bc = invert_rows(t_bc, q_bc)
    out: FloatArray = transform_points(t_bc, q_bc, p_cam)
    out[~ok] = np.nan  # no camera pose at the shifted time
    return out


def body_from_mount_parent(inputs: ChainInputs, q_bc: FloatArray) -> FloatArray:
    """(N, 4) the rotation of the camera mount's parent frame in the body at each observation (R_body_parent =
    R_body_cam R_link_cam^T R_parent_link^T; the identity without a static mount)."""
    mount = inputs.mount
    if mount is None:
        return np.tile([0.0, 0.0, 0.0, 1.0], (len(inputs), 1))
    link_from_parent = quat_multiply(quat_conjugate(mount.q_link_cam), quat_conjugate(mount.q_parent_link))
    out: FloatArray = quat_multiply(np.asarray(q_bc).T, np.asarray(link_from_parent)[:, None]).T
    return out


def _rig_mounts(inputs: ChainInputs, pert: Perturbation, t_bc: FloatArray, q_bc: FloatArray
                ) -> tuple[FloatArray, FloatArray]:
    """T_body_cam of every row with its rig camera's mount rotation and translation changed."""
    index = inputs.camera_index
    assert index is not None
    q_out, t_out = q_bc, t_bc
    for k, delta in pert.cameras.items():
        turned, moved = bool(np.any(delta.rotvec_mount)), bool(np.any(delta.translation_m))
        if not (turned or moved):
            continue
        rows = index == k
        if turned:
            mount = inputs.rig_cameras[k].mount
            q_link_cam = mount.q_link_cam if mount is not None else np.array([0.0, 0.0, 0.0, 1.0])
            rotvec_cam = quat_rotate(quat_conjugate(q_link_cam), np.asarray(delta.rotvec_mount, dtype=float))
            q_out = q_out.copy() if q_out is q_bc else q_out
            q_out[rows] = quat_multiply(np.asarray(q_bc[rows]).T, quat_from_rotvec(rotvec_cam)[:, None]).T
        if moved:
            t_out = t_out.copy() if t_out is t_bc else t_out
            t_out[rows] = t_bc[rows] + np.asarray(delta.translation_m, dtype=float)
    return t_out, q_out


def hop3(inputs: ChainInputs, pert: Perturbation, p_body: FloatArray) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """body_to_world under the perturbation, and which observations had a pose at the shifted time."""
    offsets = {k: d.offset_s for k, d in pert.cameras.items() if d.offset_s != 0.0}
    if offsets:
        t_wb, q_wb, ok = inputs.world_from_body_rows(pert.pose_offset_s, offsets, pert.world, pert.body_frame)
    else:
        t_wb, q_wb, ok = inputs.world_from_body(pert.pose_offset_s, pert.world, pert.body_frame)
    if pert.invert_pose:
        t_wb, q_wb = invert_rows(t_wb, q_wb)
    return transform_points(t_wb, q_wb, p_body), ok


def evaluate(inputs: ChainInputs, pert: Perturbation) -> tuple[FloatArray, FloatArray, FloatArray]:
    """All three hops under the perturbation: (p_cam, p_body, p_world), NaN where a pose is missing."""
    p_cam = hop1(inputs, pert)
    p_body = hop2(inputs, pert, p_cam)
    p_world, ok = hop3(inputs, pert, p_body)
    p_world[~ok] = np.nan
    return p_cam, p_body, p_world
