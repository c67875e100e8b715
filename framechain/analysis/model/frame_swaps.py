"""Wrong frames: a lookup that named another frame of the log than the chain's.

The commonest real chain fault is not a bad number but a bad name: the robot looked up
``camera_link`` where the detection was in ``camera_color_optical_frame`` (the whole optical edge
dropped, its REP-103 rotation and its translation), ``base_footprint`` for ``base_link``, ``odom``
for ``map``, or a sibling camera's frame. Each is a model with no parameters: the chain with one
lookup renamed, over the frames the log really has near the chain's own.

What a swap is called follows from the edges it skips: on the camera-to-body path, a relative
rotation that is a signed axis permutation (the optical edge) is an ``axis_flip``, any other
rotation a ``rotation_error``, a translation alone a ``wrong_camera_frame``; on the body-to-world
path every swap is a ``wrong_world_frame``. The estimate names the frame looked up, the frame
meant and the edges between them.
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace

import numpy as np

from framechain.analysis.model.chain import ChainInputs
from framechain.analysis.model.estimates import FrameEstimate
from framechain.analysis.model.fault import FaultModel, Mode
from framechain.arrays import FloatArray
from framechain.catalogue import Fault, HopName
from framechain.geometry.rotations import (
    quat_angle,
    quat_angle_between,
    quat_conjugate,
    quat_from_rotvec,
    quat_rotate,
    quat_to_matrix,
)
from framechain.replay import TransformBuffer

#: How far (edges in the frame tree) from the chain's frame a frame may be to be a candidate.
NEIGHBOURHOOD_EDGES = 3
#: At most this many candidates per path (the nearest first): each is one more hypothesis.
MAX_CANDIDATES = 16
#: Below this a relative rotation is none (degrees), and a rotation matrix entry is 0 or +-1.
SAME_ROTATION_DEG = 0.5
PERMUTATION_TOLERANCE = 1e-3
#: Frames whose distance from the chain's frame is below this are the same place (metres).
SAME_PLACE_M = 1e-4


def _tree_distances(buffer: TransformBuffer, start: str) -> dict[str, int]:
    """Edges between ``start`` and every frame of its tree (breadth first over parent and child links)."""
    neighbours: dict[str, list[str]] = {}
    for child, edge in buffer.edges.items():
        neighbours.setdefault(child, []).append(edge.parent)
        neighbours.setdefault(edge.parent, []).append(child)
    distance = {start: 0}
    queue = deque([start])
    while queue:
        frame = queue.popleft()
        for other in neighbours.get(frame, ()):
            if other not in distance:
                distance[other] = distance[frame] + 1
                queue.append(other)
    return distance


def _subtree(buffer: TransformBuffer, root: str) -> set[str]:
    """``root`` and every frame below it."""
    children: dict[str, list[str]] = {}
    for child, edge in buffer.edges.items():
        children.setdefault(edge.parent, []).append(child)
    out, stack = {root}, [root]
    while stack:
        for child in children.get(stack.pop(), ()):
            if child not in out:
                out.add(child)
                stack.append(child)
    return out


def _relative(buffer: TransformBuffer, target: str, source: str, stamp_ns: int) -> tuple[FloatArray, FloatArray] | None:
    """T_target_source at one stamp (translation, quaternion xyzw), or None when it cannot be looked up."""
    result = buffer.lookup(target, source, np.array([stamp_ns], dtype=np.int64))
    if not bool(result.ok[0]):
        return None
    return result.translation[0], result.quat_xyzw[0]


def _skipped_edges(buffer: TransformBuffer, used: str, meant: str) -> tuple[tuple[str, str], ...]:
    path = buffer.path(used, meant)
    return tuple((hop.parent, hop.child) for hop in path.hops)


def is_signed_permutation(quat_xyzw: FloatArray) -> bool:
    """Whether a rotation permutes and flips axes (every matrix entry 0 or +-1), the identity excluded."""
    matrix = quat_to_matrix(quat_xyzw)
    entries = np.abs(matrix)
    whole = np.all((entries < PERMUTATION_TOLERANCE) | (np.abs(entries - 1.0) < PERMUTATION_TOLERANCE))
    return bool(whole) and not np.allclose(matrix, np.eye(3), atol=PERMUTATION_TOLERANCE)


def camera_swap_fault(quat_xyzw: FloatArray) -> Fault:
    """The catalogue entry of looking up a frame whose rotation from the camera frame is ``quat_xyzw``."""
    if is_signed_permutation(quat_xyzw):
        return Fault.AXIS_FLIP
    if np.rad2deg(quat_angle(quat_xyzw)) > SAME_ROTATION_DEG:
        return Fault.ROTATION_ERROR
    return Fault.WRONG_CAMERA_FRAME


def _candidates(buffer: TransformBuffer, meant: str, exclude: set[str], connected_to: str) -> list[str]:
    distance = _tree_distances(buffer, meant)
    near = sorted(
        (d, frame) for frame, d in distance.items()
        if 0 < d <= NEIGHBOURHOOD_EDGES and frame not in exclude
    )
    out = []
    for _d, frame in near:
        if buffer.path(connected_to, frame).connected:
            out.append(frame)
        if len(out) == MAX_CANDIDATES:
            break
    return out


def camera_frame_candidates(inputs: ChainInputs) -> list[tuple[str, Fault]]:
    """Frames the robot may have looked up instead of the chain's camera frame, with the fault each is.

    Frames near the camera in the tree (its link, the camera's other frames, a sibling camera's),
    never the body side (the body, its ancestors: those are the body-to-world hop) and never a
    frame at the camera's own place and orientation (a swap that changes nothing).
    """
    buffer, frames = inputs.buffer, inputs.frames
    # The camera's side of the tree: everything under the frame the camera path enters the body by
    # (camera_link, a mast, the arm's first link); the body's other children (wheels, a footprint)
    # are not the camera's.
    path = buffer.path(frames.body, frames.camera).frames
    mount_root = path[-2] if len(path) >= 2 else frames.camera
    camera_side = _subtree(buffer, mount_root)
    exclude = set(buffer.frames) - camera_side
    stamp = int(inputs.stamp_ns[0])
    out: list[tuple[str, Fault]] = []
    for frame in _candidates(buffer, frames.camera, exclude, frames.body):
        relative = _relative(buffer, frame, frames.camera, stamp)
        if relative is None:
            continue
        translation, quat = relative
        fault = camera_swap_fault(quat)
        if fault == Fault.WRONG_CAMERA_FRAME and np.linalg.norm(translation) < SAME_PLACE_M:
            continue
        out.append((frame, fault))
    return out


def body_frame_candidates(inputs: ChainInputs) -> list[str]:
    """Frames the robot may have looked up instead of the chain's body (base_footprint for base_link).

    Frames near the body in the tree, neither on the camera's side of the body nor the world
    frames, at another place or orientation than the body.
    """
    buffer, frames = inputs.buffer, inputs.frames
    camera_side = set(buffer.path(frames.body, frames.camera).frames)
    world_side = set(buffer.path(frames.world, frames.body).frames) - {frames.body}
    # The body's own ancestors (base_footprint above base_link) are candidates; the world frames are not.
    exclude = camera_side | {frames.world} | (world_side - _near_ancestors(buffer, frames.body, frames.world))
    stamp = int(inputs.stamp_ns[0])
    out = []
    for frame in _candidates(buffer, frames.body, exclude, frames.world):
        relative = _relative(buffer, frame, frames.body, stamp)
        if relative is None:
            continue
        translation, quat = relative
        if np.linalg.norm(translation) < SAME_PLACE_M and np.rad2deg(quat_angle(quat)) < 1e-3:
            continue
        out.append(frame)
    return out


def _near_ancestors(buffer: TransformBuffer, body: str, world: str) -> set[str]:
    """The body's ancestors below the world whose edge to the next is static (base_footprint, not odom)."""
    out: set[str] = set()
    frame = body
    edges = buffer.edges
    while frame in edges and edges[frame].parent != world:
        parent = edges[frame].parent
        if not edges[frame].is_static:
            break
        out.add(parent)
        frame = parent
    return out


def _swap(frame: str, meant: str, fault: Fault, hop: HopName, inputs: ChainInputs) -> FaultModel:
    """The chain with ``hop``'s lookup naming ``frame`` instead of ``meant`` (the camera or the body frame)."""
    skipped = _skipped_edges(inputs.buffer, frame, meant)
    camera = hop == HopName.CAMERA_TO_BODY

    def estimate(x: FloatArray, mode: Mode, chain: ChainInputs) -> FrameEstimate:
        # As run: the robot looked up ``frame``. As a correction: the recorded data says ``meant``
        # where the detections really are in ``frame``.
        used, right = (frame, meant) if mode == "as_run" else (meant, frame)
        return FrameEstimate(used=used, meant=right, hop=hop.value, skipped=skipped)

    return FaultModel(
        name=f"frame_swap[{'camera' if camera else 'body'}:{frame}]",
        fault=fault,
        hop=hop,
        family="camera_rotation" if camera else "world_frame",
        apply=(lambda p, x: replace(p, camera_frame=frame)) if camera else (lambda p, x: replace(p, body_frame=frame)),
        estimate=estimate,
        choice_penalty=float(np.log(max(2.0, 1.0 + MAX_CANDIDATES))),
    )


def frame_swap_models(inputs: ChainInputs, *, blind: bool = False) -> list[FaultModel]:
    """Every "looked up frame X instead of Y" hypothesis this log's frame tree allows.

    ``blind`` (a static target alone) keeps the camera side only: a body-side swap moves every
    world point of a static target alike while the robot stands, and mostly says nothing.
    """
    if len(inputs) == 0:
        return []
    frames = inputs.frames
    models = [_swap(frame, frames.camera, fault, HopName.CAMERA_TO_BODY, inputs)
              for frame, fault in camera_frame_candidates(inputs)]
    if not blind:
        models += [_swap(frame, frames.body, Fault.WRONG_WORLD_FRAME, HopName.BODY_TO_WORLD, inputs)
                   for frame in body_frame_candidates(inputs)]
    return models


def swap_for_rotation(inputs: ChainInputs, rotvec_mount: FloatArray) -> str | None:
    """The camera-side frame whose swap is the fitted mount rotation (within noise), if any.

    A rotation fit that lands on the rotation of a path edge (the REP-103 optical rotation, say)
    is that edge skipped, not a mis-calibrated mount: the caller then prefers the swap.
    """
    q_link_cam = inputs.mount.q_link_cam if inputs.mount is not None else np.array([0.0, 0.0, 0.0, 1.0])
    # R_bc' = R_bc exp(R_cam_link x): the change of the camera rotation in the camera frame.
    change_cam = quat_from_rotvec(quat_rotate(quat_conjugate(q_link_cam), np.asarray(rotvec_mount, dtype=float)))
    stamp = int(inputs.stamp_ns[0])
    for frame, _fault in camera_frame_candidates(inputs):
        relative = _relative(inputs.buffer, inputs.frames.camera, frame, stamp)
        if relative is None:
            continue
        # Looking up ``frame`` uses R_b_frame = R_bc R_c_frame: the camera rotation changed by R_c_frame.
        if np.rad2deg(quat_angle_between(relative[1], change_cam)) < 2.0:
            return frame
    return None
