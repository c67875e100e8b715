"""The scene of a Rerun recording: the log's frame tree, the transforms the replay used, the camera (pinhole,
depth frames, detections), its images and the chain drawn on them."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from framechain.arrays import FloatArray, IntArray
from framechain.config.chain import ChainFrames
from framechain.replay import REPLAYED, ReplayResult
from framechain.replay.stamps import nearest
from framechain.sinks.colors import (
    AS_RUN_COLOR,
    DETECTION_COLOR,
    ERROR_COLOR,
    RECOMPUTED_COLOR,
    STALE_COLOR,
)
from framechain.sinks.overlay import ImageOverlay, select_images
from framechain.sinks.rerun_common import (
    OBS_INDEX,
    REPLAY_FRAME_SUFFIX,
    CameraView,
    Clock,
    RerunOptions,
    entity_part,
    rerun_intrinsics,
    rerun_pixels,
    send_per_stamp,
)
from framechain.timeline import ImageFrameTable, Timeline, normalize_frame
from framechain.timeline.frames import COMPRESSED_IMAGE_ENCODINGS, RAW_IMAGE_ENCODINGS

if TYPE_CHECKING:
    import rerun as rr

#: A rig's cameras sit centimetres apart: their frustums are drawn short.
RIG_PLANE_DISTANCE_M = 0.1
BORDER_COLOR = (160, 160, 160)
#: The chain's frames' names in 3D: dark, as the viewer writes text.
LABEL_COLOR = (40, 40, 40)


def log_frame_tree(
    rec: rr.RecordingStream, timeline: Timeline, clock: Clock, frames: ChainFrames, opts: RerunOptions,
    rows: dict[str, int], cameras: tuple[str, ...] = (), *, replayed: bool = True,
) -> None:
    """``/tf/<child>`` per child frame: static edges once as static, dynamic edges in bulk; ``/frames/<frame>`` the
    axes of every frame, named only where the frame is one of the chain's (world, body, camera; ``cameras``: a rig's
    other cameras): an arm's dozen links would bury each other's names. Chain frames that sit at one place (a
    world that is the arm's base) share one label. A frame's ``@replay`` copy is named only where the log's tree
    lacks the frame: both sit at one place when the replay used the log's transforms; without a replayed
    observation (``replayed`` False) there are no copies, whose frames nothing would place."""
    import rerun as rr

    tf = timeline.transforms
    in_tree = {str(f) for f in np.unique(np.concatenate([tf.child, tf.parent]))} if len(tf) else set()
    names: set[str] = {frames.world, frames.body, frames.camera, *cameras}
    for child in np.unique(tf.child):
        sel = np.flatnonzero(tf.child == child)
        entity = f"/tf/{entity_part(str(child))}"
        names.add(str(child))
        names.update(str(p) for p in np.unique(tf.parent[sel]))
        dynamic = sel[~tf.is_static[sel]]
        if dynamic.size == 0:
            # Static data has no time and overrides temporal data: the latest static sample only.
            last = sel[np.argmax(tf.stamp_ns[sel])]
            rec.log(entity, rr.Transform3D(
                translation=tf.translation[last], quaternion=tf.quat_xyzw[last],
                parent_frame=str(tf.parent[last]), child_frame=str(child),
            ), static=True)
            rows[entity] = 1
            continue
        # A child with dynamic samples stays temporal (static samples of it, if any, at their stamps).
        use = sel[np.argsort(tf.stamp_ns[sel], kind="stable")]
        rec.send_columns(
            entity,
            indexes=clock.columns(tf.stamp_ns[use], tf.log_time_ns[use]),
            columns=rr.Transform3D.columns(
                translation=tf.translation[use], quaternion=tf.quat_xyzw[use],
                parent_frame=tf.parent[use].tolist(), child_frame=tf.child[use].tolist(),
            ),
        )
        rows[entity] = int(use.size)
    chain = (frames.world, frames.body, frames.camera, *cameras)
    if replayed:
        names.update(c + REPLAY_FRAME_SUFFIX for c in chain[1:])
    _log_frame_axes(rec, names, in_tree, frame_labels(timeline, chain, anchors=(frames.camera, *cameras)),
                    cameras if len(cameras) > 1 else (), opts, rows)


def _log_frame_axes(rec: rr.RecordingStream, names: set[str], in_tree: set[str], labels: dict[str, str],
                    rig: tuple[str, ...], opts: RerunOptions, rows: dict[str, int]) -> None:
    """``/frames/<frame>``: every frame's axes, and the chain frames' ``labels`` (a ``rig``'s cameras sit
    centimetres apart: each is named past its frustum, along its view, where they part)."""
    import rerun as rr

    for name in sorted(names):
        recorded = name.removesuffix(REPLAY_FRAME_SUFFIX)
        replay_copy = name.endswith(REPLAY_FRAME_SUFFIX)
        entity = f"/frames/replay/{entity_part(recorded)}" if replay_copy else f"/frames/{entity_part(name)}"
        rec.log(entity, rr.CoordinateFrame(name), rr.TransformAxes3D(opts.axis_length_m, show_frame=False),
                static=True)
        # a chain frame the log's tree lacks is named on its replay copy, where the replay put it
        on_copy = recorded not in in_tree and recorded + REPLAY_FRAME_SUFFIX in names
        label = labels.get(recorded) if replay_copy == on_copy else None
        if label is not None:
            ahead = 2.5 * RIG_PLANE_DISTANCE_M if recorded in rig else 0.0
            rec.log(entity, rr.Points3D([[0.0, 0.0, ahead]], radii=[opts.axis_length_m / 25], colors=[LABEL_COLOR],
                                        labels=[label], show_labels=True), static=True)
        rows[entity] = 1


def frame_labels(timeline: Timeline, chain: tuple[str, ...], anchors: tuple[str, ...] = ()) -> dict[str, str]:
    """The label of each chain frame that gets one: its name; chain frames that static edges without translation
    (under 1 mm) join share one label, ``"world = base_link"``, on the first of them in ``chain`` (the first of
    ``anchors``, cameras, among them when there is one) and the others get none."""
    tf = timeline.transforms
    static = np.flatnonzero(tf.is_static & (np.linalg.norm(tf.translation, axis=1) < 1e-3)).tolist() if len(tf) else []
    group = {frame: frame for frame in chain}

    def root(frame: str) -> str:
        while group.get(frame, frame) != frame:
            frame = group[frame]
        return frame

    for i in static:
        a, b = root(str(tf.parent[i])), root(str(tf.child[i]))
        if a != b:
            group[b] = a
    members: dict[str, list[str]] = {}
    for frame in dict.fromkeys(chain):
        members.setdefault(root(frame), []).append(frame)
    return {next((f for f in together if f in anchors), together[0]): " = ".join(together)
            for together in members.values()}


def log_used_transforms(rec: rr.RecordingStream, result: ReplayResult, clock: Clock, views: list[CameraView],
                        rows: dict[str, int]) -> None:
    """The transforms the replay used, per replayed observation, at the observation's time (body -> camera per
    camera of a rig)."""
    import rerun as rr

    frames = result.frames
    body_replay = frames.body + REPLAY_FRAME_SUFFIX
    ok = np.flatnonzero(result.replayed)
    if ok.size == 0:
        return
    used = [("/replay/world_from_body", result.world_from_body, frames.world, body_replay, ok)]
    for view in views:
        mine = np.intersect1d(view.rows, ok)
        used.append((view.entity("/replay/body_from_cam", "/replay/body_from_cam"), result.body_from_cam,
                     body_replay, view.frame + REPLAY_FRAME_SUFFIX, mine))
    for entity, lookup, parent, child, sel in used:
        if sel.size == 0:
            continue
        rec.send_columns(
            entity, indexes=clock.obs_indexes(result, sel),
            columns=rr.Transform3D.columns(
                translation=lookup.translation[sel], quaternion=lookup.quat_xyzw[sel],
                parent_frame=[parent] * sel.size, child_frame=[child] * sel.size,
            ),
        )
        rows[entity] = int(sel.size)


def log_camera(
    rec: rr.RecordingStream, timeline: Timeline, result: ReplayResult, clock: Clock, view: CameraView,
    opts: RerunOptions, rows: dict[str, int],
) -> None:
    """One camera: its pinhole (static, or over time if the intrinsics change) and depth frames."""
    import rerun as rr

    plane = view.plane
    root = view.root
    cams = timeline.cameras
    # A model without an image (width 0: 3D points in the camera frame, no intrinsics) has no pinhole to show,
    # and its detections are no pixels.
    on_frame = cams.frame == normalize_frame(view.frame)
    mine = np.flatnonzero(on_frame & (cams.width > 0))
    if mine.size:
        mine = mine[np.argsort(cams.stamp_ns[mine], kind="stable")]
        k = cams.K[mine]
        res = np.stack([cams.width[mine], cams.height[mine]], axis=1).astype(float)
        changes = np.concatenate([[True], (np.abs(np.diff(k, axis=0)).max(axis=(1, 2)) > 0)
                                  | (np.diff(res, axis=0) != 0).any(axis=1)])
        keep = mine[changes]
        if keep.size == 1:
            rec.log(root, rr.Pinhole(
                image_from_camera=rerun_intrinsics(cams.K[keep[0]]), resolution=res[changes][0],
                camera_xyz=rr.ViewCoordinates.RDF, parent_frame=view.frame, child_frame=plane,
                image_plane_distance=RIG_PLANE_DISTANCE_M if view.rig else 0.5,
            ), static=True)
        else:
            rec.send_columns(
                root,
                indexes=clock.columns(cams.stamp_ns[keep], cams.log_time_ns[keep]),
                columns=rr.Pinhole.columns(
                    image_from_camera=rerun_intrinsics(cams.K[keep]), resolution=res[changes],
                    camera_xyz=[rr.ViewCoordinates.RDF] * keep.size,
                    parent_frame=[view.frame] * keep.size, child_frame=[plane] * keep.size,
                ),
            )
        rows[root] = int(keep.size)
        if view.rig:  # without images a view shows where the image ends by its border
            width, height = res[changes][-1]
            rec.log(f"{root}/border", rr.LineStrips2D([[(0, 0), (width, 0), (width, height), (0, height), (0, 0)]],
                                                      colors=[BORDER_COLOR]), rr.CoordinateFrame(plane), static=True)
            rows[f"{root}/border"] = 1
    log_depth(rec, timeline, result, clock, view, opts, rows)


def log_detections(rec: rr.RecordingStream, overlay: ImageOverlay, result: ReplayResult, clock: Clock,
                   view: CameraView, rows: dict[str, int]) -> None:
    """A camera's detections in its image: ``detections``, the pixel framechain used per observation (green where
    it is the detector's own, light green where framechain estimated it, red when rejected, light red when stale),
    and ``overlay/detector_centre``, the centre the detector logged where framechain used its own estimate."""
    import rerun as rr

    obs = result.observations
    drawn = view.rows[np.isfinite(overlay.detection_uv[view.rows]).all(axis=1)]  # a camera-less model: no pixels
    if drawn.size == 0:
        return
    colors = overlay.detection_colors
    colors[~result.replayed] = ERROR_COLOR
    colors[result.stale] = STALE_COLOR
    labels = {int(r): f"obs {obs.obs_id[r]} {obs.label[r]}".rstrip()
              + ("" if result.status[r] == REPLAYED else f" ({result.status[r]})") for r in drawn.tolist()}
    radii = np.where(overlay.estimated, 4.0, 6.0)
    entity = f"{view.root}/detections"
    rec.log(entity, rr.CoordinateFrame(view.plane), static=True)
    send_per_stamp(rec, entity, result, clock, drawn, lambda sel: rr.Points2D.columns(
        positions=rerun_pixels(overlay.detection_uv[sel]), colors=colors[sel],
        labels=[labels[i] for i in sel.tolist()], radii=radii[sel]))
    rows[entity] = int(drawn.size)
    logged = drawn[overlay.estimated[drawn] & np.isfinite(overlay.detector_uv[drawn]).all(axis=1)]
    if logged.size:
        entity = f"{view.root}/overlay/detector_centre"
        # under the pixel framechain used (Points2D draw at 30 by default)
        rec.log(entity, rr.CoordinateFrame(view.plane), rr.Points2D.from_fields(draw_order=20.0), static=True)
        send_per_stamp(rec, entity, result, clock, logged, lambda sel: rr.Points2D.columns(
            positions=rerun_pixels(overlay.detector_uv[sel]),
            colors=np.tile(np.array(DETECTION_COLOR, dtype=np.uint8), (sel.size, 1)),
            radii=np.full(sel.size, 7.0), labels=[f"obs {i}: the detector's logged centre" for i in
                                                  obs.obs_id[sel].tolist()],
            show_labels=[False] * sel.size))
        rows[entity] = int(logged.size)


def log_images(
    rec: rr.RecordingStream, timeline: Timeline, result: ReplayResult, clock: Clock, view: CameraView,
    opts: RerunOptions, rows: dict[str, int],
) -> None:
    """A camera's images under its image plane: raw as ``Image``, JPEG/PNG as ``EncodedImage`` (bytes
    as logged), frames of a video file as ``VideoFrameReference`` into one ``AssetVideo`` per file."""
    import rerun as rr

    images = timeline.image_frames
    chosen = select_images(timeline, result, opts.images, camera=view.frame if view.rig else None)
    if chosen.size == 0:
        return
    plane = view.plane
    image_entity = f"{view.root}/image"
    enc = images.encoding[chosen]
    raw = chosen[np.isin(enc, list(RAW_IMAGE_ENCODINGS))]
    compressed = chosen[np.isin(enc, list(COMPRESSED_IMAGE_ENCODINGS))]
    if raw.size or compressed.size:
        rec.log(image_entity, rr.CoordinateFrame(plane), static=True)
    if raw.size:
        rec.send_columns(
            image_entity, indexes=_image_indexes(images, result, clock, raw),
            columns=rr.Image.columns(buffer=[images.load(int(i)) for i in raw],
                                     format=[_image_format(str(images.encoding[i]), int(images.width[i]),
                                                           int(images.height[i])) for i in raw]),
        )
    if compressed.size:
        rec.send_columns(
            image_entity, indexes=_image_indexes(images, result, clock, compressed),
            columns=rr.EncodedImage.columns(blob=[images.load(int(i)) for i in compressed],
                                            media_type=[f"image/{images.encoding[i]}" for i in compressed]),
        )
    if raw.size or compressed.size:
        rows[image_entity] = int(raw.size + compressed.size)
    video = chosen[images.video_frames[chosen]]
    for k, path in enumerate(np.unique(images.video_path[video]).tolist()):
        entity = f"{view.root}/video" if k == 0 else f"{view.root}/video/{k}"
        frames = video[images.video_path[video] == path]
        rec.log(entity, rr.AssetVideo(path=path), rr.CoordinateFrame(plane), static=True)
        rec.send_columns(entity, indexes=_image_indexes(images, result, clock, frames),
                         columns=rr.VideoFrameReference.columns_nanos(images.video_time_ns[frames]))
        rows[entity] = int(frames.size)


def _image_format(encoding: str, width: int, height: int) -> rr.components.ImageFormat:
    import rerun as rr

    channels, dtype = RAW_IMAGE_ENCODINGS[encoding]
    bgr = encoding.startswith("bgr")
    models: dict[int, Literal["L", "RGB", "BGR", "RGBA", "BGRA"]] = {
        1: "L", 3: "BGR" if bgr else "RGB", 4: "BGRA" if bgr else "RGBA"}
    datatypes: dict[str, Literal["U8", "U16", "F32"]] = {"u1": "U8", "<u2": "U16", "<f4": "F32"}
    return rr.components.ImageFormat(width=width, height=height, color_model=models[channels],
                                     channel_datatype=datatypes[dtype])


def _image_indexes(images: ImageFrameTable, result: ReplayResult, clock: Clock, rows: IntArray) -> list[rr.TimeColumn]:
    """Sensor and log time of each image, and the row of the observation nearest it (so images
    follow the ``obs_index`` timeline too)."""
    import rerun as rr

    obs = result.observations
    order = np.argsort(obs.stamp_ns, kind="stable")
    if obs.stamp_ns.size:
        near = order[nearest(obs.stamp_ns[order], images.stamp_ns[rows])]
    else:
        near = np.zeros(rows.size, dtype=np.int64)
    return [*clock.columns(images.stamp_ns[rows], images.log_time_ns[rows]),
            rr.TimeColumn(OBS_INDEX, sequence=near.astype(np.int64))]


def log_overlay(rec: rr.RecordingStream, overlay: ImageOverlay, result: ReplayResult, clock: Clock,
                view: CameraView, rows: dict[str, int]) -> None:
    """The chain on a camera's image: corners, projected recomputed and as-run points, the line between them.

    Observations with one stamp (several tags in one image) share one row per entity, so the viewer
    shows all of them at that time (a later row at the same time would hide the earlier ones).
    """
    import rerun as rr

    if view.rows.size == 0:
        return
    plane = view.plane
    mine = np.zeros(len(result.observations), dtype=bool)
    mine[view.rows] = True

    def send(entity: str, sel: IntArray, columns: Callable[[IntArray], rr.ComponentColumnList]) -> None:
        sel = sel[mine[sel]]
        if sel.size == 0:
            return
        rec.log(entity, rr.CoordinateFrame(plane), static=True)
        send_per_stamp(rec, entity, result, clock, sel, columns)
        rows[entity] = int(sel.size)

    radius = np.float32(max(2.0, float(np.nanmax(overlay.width, initial=320)) / 160.0))
    corners = np.flatnonzero(np.isfinite(overlay.corners_px).all(axis=(1, 2)))
    send(f"{view.root}/overlay/corners", corners, lambda sel: rr.LineStrips2D.columns(
        strips=[rerun_pixels(np.vstack([q, q[:1]])) for q in overlay.corners_px[sel]],
        colors=np.tile(np.array(DETECTION_COLOR, dtype=np.uint8), (sel.size, 1)),
        radii=np.full(sel.size, radius / 2, dtype=np.float32)))
    def points(uv: FloatArray, color: tuple[int, int, int], what: str) -> Callable[[IntArray], rr.ComponentColumnList]:
        def columns(sel: IntArray) -> rr.ComponentColumnList:
            return rr.Points2D.columns(
                positions=rerun_pixels(uv[sel]), colors=np.tile(np.array(color, dtype=np.uint8), (sel.size, 1)),
                radii=np.full(sel.size, radius * 1.5, dtype=np.float32), labels=[what] * sel.size,
                show_labels=[False] * sel.size)

        return columns

    for name, uv, color in (("recomputed", overlay.recomputed_uv, RECOMPUTED_COLOR),
                            ("as_run", overlay.as_run_uv, AS_RUN_COLOR)):
        have = np.flatnonzero(np.isfinite(uv).all(axis=1))
        what = "recomputed world point" if name == "recomputed" else f"as-run {overlay.as_run_role} point"
        send(f"{view.root}/overlay/{name}", have, points(uv, color, what))
    both = np.flatnonzero(np.isfinite(overlay.recomputed_uv).all(axis=1) & np.isfinite(overlay.as_run_uv).all(axis=1))
    error_px = overlay.error_px
    send(f"{view.root}/overlay/error", both, lambda sel: rr.LineStrips2D.columns(
        strips=[rerun_pixels(np.stack([overlay.recomputed_uv[i], overlay.as_run_uv[i]])) for i in sel.tolist()],
        colors=np.tile(np.array(overlay.color, dtype=np.uint8), (sel.size, 1)),
        radii=np.full(sel.size, radius / 2, dtype=np.float32),
        labels=[f"{error_px[i]:.0f} px: {overlay.label()}" for i in sel.tolist()]))
    both = both[mine[both]]
    if both.size:
        entity = view.entity("/series/error_px", "/series/error_px/as_run")
        rec.log(entity, rr.SeriesLines(names=["as-run vs recomputed in the image (px)"], colors=[overlay.color]),
                static=True)
        rec.send_columns(entity, indexes=clock.obs_indexes(result, both),
                         columns=rr.Scalars.columns(scalars=error_px[both]))
        rows[entity] = int(both.size)


def log_depth(
    rec: rr.RecordingStream, timeline: Timeline, result: ReplayResult, clock: Clock, view: CameraView,
    opts: RerunOptions, rows: dict[str, int],
) -> None:
    """Depth frames of a camera near its observations, decimated to ``max_images``.

    Logged as uint16 millimetres (``meter=1000``): a VGA frame is 0.6 MB, so the default cap of 30
    keeps a recording under about 20 MB; lazily decoded frames cost about 70 ms each from an MCAP.
    """
    import rerun as rr

    depth = timeline.depth_frames
    mine = np.flatnonzero(depth.frame == normalize_frame(view.frame))
    obs = result.observations
    if mine.size == 0 or view.rows.size == 0 or opts.max_images <= 0 or depth.loader is None:
        return
    mine = mine[np.argsort(depth.stamp_ns[mine], kind="stable")]
    stamps = depth.stamp_ns[mine]
    # The frame each observation used (or the nearest within the window when depth came with it).
    want = np.where(result.depth_stamp_ns > 0, result.depth_stamp_ns, obs.stamp_ns)[view.rows]
    pick = nearest(stamps, want)
    near = np.abs(stamps[pick] - want) <= opts.image_window_ns
    chosen = np.unique(mine[pick[near]])
    if chosen.size > opts.max_images:
        chosen = chosen[np.linspace(0, chosen.size - 1, opts.max_images).round().astype(np.int64)]
        chosen = np.unique(chosen)
    images = [_depth_mm(depth.load(int(i))) for i in chosen]
    formats = [rr.components.ImageFormat(width=im.shape[1], height=im.shape[0], channel_datatype="U16")
               for im in images]
    entity = f"{view.root}/depth"
    rec.log(entity, rr.CoordinateFrame(view.plane), static=True)
    rec.send_columns(
        entity,
        indexes=clock.columns(depth.stamp_ns[chosen], depth.log_time_ns[chosen]),
        columns=rr.DepthImage.columns(buffer=[im.tobytes() for im in images], format=formats,
                                      meter=np.full(chosen.size, 1000.0, dtype=np.float32)),
    )
    rows[entity] = int(chosen.size)


def _depth_mm(image_m: npt.NDArray[np.float32]) -> npt.NDArray[np.uint16]:
    """Depth in metres as uint16 millimetres (half the bytes of float32); 0 where there is none."""
    mm = np.asarray(image_m, dtype=np.float64) * 1000.0
    valid = np.isfinite(mm) & (mm > 0) & (mm < 65535.5)
    return np.ascontiguousarray(np.where(valid, np.rint(mm), 0).astype(np.uint16))
