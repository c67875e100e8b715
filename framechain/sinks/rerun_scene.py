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
from framechain.sinks.overlay import (
    AS_RUN_COLOR,
    DETECTION_COLOR,
    RECOMPUTED_COLOR,
    ImageOverlay,
    select_images,
)
from framechain.sinks.rerun_common import (
    ERROR_COLOR,
    IMAGE_PLANE_SUFFIX,
    LOG_TIME,
    OBS_INDEX,
    REPLAY_FRAME_SUFFIX,
    SENSOR_TIME,
    STALE_COLOR,
    RerunOptions,
    entity_part,
    obs_indexes,
    send_per_stamp,
    stamp_column,
)
from framechain.timeline import ImageFrameTable, Timeline, normalize_frame
from framechain.timeline.frames import COMPRESSED_IMAGE_ENCODINGS, RAW_IMAGE_ENCODINGS, VIDEO_ENCODING

if TYPE_CHECKING:
    import rerun as rr


def log_frame_tree(
    rec: rr.RecordingStream, timeline: Timeline, frames: ChainFrames, opts: RerunOptions, rows: dict[str, int]
) -> None:
    """``/tf/<child>`` per child frame: static edges once as static, dynamic edges in bulk."""
    import rerun as rr

    tf = timeline.transforms
    names: set[str] = {frames.world, frames.body, frames.camera}
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
            indexes=[stamp_column(SENSOR_TIME, tf.stamp_ns[use]), stamp_column(LOG_TIME, tf.log_time_ns[use])],
            columns=rr.Transform3D.columns(
                translation=tf.translation[use], quaternion=tf.quat_xyzw[use],
                parent_frame=tf.parent[use].tolist(), child_frame=tf.child[use].tolist(),
            ),
        )
        rows[entity] = int(use.size)
    names.update({frames.body + REPLAY_FRAME_SUFFIX, frames.camera + REPLAY_FRAME_SUFFIX})
    for name in sorted(names):
        if name.endswith(REPLAY_FRAME_SUFFIX):
            entity = f"/frames/replay/{entity_part(name.removesuffix(REPLAY_FRAME_SUFFIX))}"
        else:
            entity = f"/frames/{entity_part(name)}"
        rec.log(entity, rr.CoordinateFrame(name), rr.TransformAxes3D(opts.axis_length_m, show_frame=True),
                static=True)
        rows[entity] = 1


def log_used_transforms(rec: rr.RecordingStream, result: ReplayResult, rows: dict[str, int]) -> None:
    """The transforms the replay used, per replayed observation, at the observation's time."""
    import rerun as rr

    frames = result.frames
    body_replay = frames.body + REPLAY_FRAME_SUFFIX
    cam_replay = frames.camera + REPLAY_FRAME_SUFFIX
    ok = np.flatnonzero(result.replayed)
    if ok.size == 0:
        return
    for entity, lookup, parent, child in (
        ("/replay/world_from_body", result.world_from_body, frames.world, body_replay),
        ("/replay/body_from_cam", result.body_from_cam, body_replay, cam_replay),
    ):
        rec.send_columns(
            entity, indexes=obs_indexes(result, ok),
            columns=rr.Transform3D.columns(
                translation=lookup.translation[ok], quaternion=lookup.quat_xyzw[ok],
                parent_frame=[parent] * ok.size, child_frame=[child] * ok.size,
            ),
        )
        rows[entity] = int(ok.size)


def log_camera(
    rec: rr.RecordingStream, timeline: Timeline, result: ReplayResult, opts: RerunOptions, rows: dict[str, int]
) -> None:
    """Pinhole (static, or over time if the intrinsics change), depth frames, detections."""
    import rerun as rr

    frames = result.frames
    plane = frames.camera + IMAGE_PLANE_SUFFIX
    cams = timeline.cameras
    # A model without an image (width 0: 3D points in the camera frame, no intrinsics) has no pinhole to show,
    # and its detections are no pixels.
    on_frame = cams.frame == normalize_frame(frames.camera)
    mine = np.flatnonzero(on_frame & (cams.width > 0))
    points_only = bool(on_frame.any()) and not mine.size
    if mine.size:
        mine = mine[np.argsort(cams.stamp_ns[mine], kind="stable")]
        k = cams.K[mine]
        res = np.stack([cams.width[mine], cams.height[mine]], axis=1).astype(float)
        changes = np.concatenate([[True], (np.abs(np.diff(k, axis=0)).max(axis=(1, 2)) > 0)
                                  | (np.diff(res, axis=0) != 0).any(axis=1)])
        keep = mine[changes]
        if keep.size == 1:
            rec.log("/camera", rr.Pinhole(
                image_from_camera=cams.K[keep[0]], resolution=res[changes][0],
                camera_xyz=rr.ViewCoordinates.RDF, parent_frame=frames.camera, child_frame=plane,
                image_plane_distance=0.5,
            ), static=True)
        else:
            rec.send_columns(
                "/camera",
                indexes=[stamp_column(SENSOR_TIME, cams.stamp_ns[keep]),
                         stamp_column(LOG_TIME, cams.log_time_ns[keep])],
                columns=rr.Pinhole.columns(
                    image_from_camera=cams.K[keep], resolution=res[changes],
                    camera_xyz=[rr.ViewCoordinates.RDF] * keep.size,
                    parent_frame=[frames.camera] * keep.size, child_frame=[plane] * keep.size,
                ),
            )
        rows["/camera"] = int(keep.size)
    log_depth(rec, timeline, result, opts, plane, rows)
    obs = result.observations
    if len(obs) and not points_only:
        every = np.arange(len(obs), dtype=np.int64)
        colors = np.where(result.replayed[:, None], np.array(RECOMPUTED_COLOR), np.array(ERROR_COLOR))
        colors[result.stale] = STALE_COLOR
        labels = [f"obs {i} {lab}".rstrip() + ("" if s == REPLAYED else f" ({s})")
                  for i, lab, s in zip(obs.obs_id.tolist(), obs.label.tolist(), result.status.tolist(), strict=True)]
        rec.log("/camera/detections", rr.CoordinateFrame(plane), static=True)
        send_per_stamp(rec, "/camera/detections", result, every, lambda sel: rr.Points2D.columns(
            positions=np.stack([obs.u[sel], obs.v[sel]], axis=1), colors=colors[sel].astype(np.uint8),
            labels=[labels[i] for i in sel.tolist()], radii=np.full(sel.size, 6.0)))
        rows["/camera/detections"] = len(obs)


def log_images(
    rec: rr.RecordingStream, timeline: Timeline, result: ReplayResult, opts: RerunOptions, rows: dict[str, int]
) -> None:
    """The camera's images under its image plane: raw as ``Image``, JPEG/PNG as ``EncodedImage`` (bytes
    as logged), frames of a video file as ``VideoFrameReference`` into one ``AssetVideo`` per file."""
    import rerun as rr

    images = timeline.image_frames
    chosen = select_images(timeline, result, opts.images)
    if chosen.size == 0:
        return
    plane = result.frames.camera + IMAGE_PLANE_SUFFIX
    enc = images.encoding[chosen]
    raw = chosen[np.isin(enc, list(RAW_IMAGE_ENCODINGS))]
    compressed = chosen[np.isin(enc, list(COMPRESSED_IMAGE_ENCODINGS))]
    if raw.size or compressed.size:
        rec.log("/camera/image", rr.CoordinateFrame(plane), static=True)
    if raw.size:
        rec.send_columns(
            "/camera/image", indexes=_image_indexes(images, result, raw),
            columns=rr.Image.columns(buffer=[images.load(int(i)) for i in raw],
                                     format=[_image_format(str(images.encoding[i]), int(images.width[i]),
                                                           int(images.height[i])) for i in raw]),
        )
    if compressed.size:
        rec.send_columns(
            "/camera/image", indexes=_image_indexes(images, result, compressed),
            columns=rr.EncodedImage.columns(blob=[images.load(int(i)) for i in compressed],
                                            media_type=[f"image/{images.encoding[i]}" for i in compressed]),
        )
    if raw.size or compressed.size:
        rows["/camera/image"] = int(raw.size + compressed.size)
    video = chosen[enc == VIDEO_ENCODING]
    for k, path in enumerate(np.unique(images.video_path[video]).tolist()):
        entity = "/camera/video" if k == 0 else f"/camera/video/{k}"
        frames = video[images.video_path[video] == path]
        rec.log(entity, rr.AssetVideo(path=path), rr.CoordinateFrame(plane), static=True)
        rec.send_columns(entity, indexes=_image_indexes(images, result, frames),
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


def _image_indexes(images: ImageFrameTable, result: ReplayResult, rows: IntArray) -> list[rr.TimeColumn]:
    """Sensor and log time of each image, and the row of the observation nearest it (so images
    follow the ``obs_index`` timeline too)."""
    import rerun as rr

    obs = result.observations
    order = np.argsort(obs.stamp_ns, kind="stable")
    if obs.stamp_ns.size:
        near = order[nearest(obs.stamp_ns[order], images.stamp_ns[rows])]
    else:
        near = np.zeros(rows.size, dtype=np.int64)
    return [stamp_column(SENSOR_TIME, images.stamp_ns[rows]), stamp_column(LOG_TIME, images.log_time_ns[rows]),
            rr.TimeColumn(OBS_INDEX, sequence=near.astype(np.int64))]


def log_overlay(rec: rr.RecordingStream, overlay: ImageOverlay, result: ReplayResult, rows: dict[str, int]) -> None:
    """The chain on the image: corners, projected recomputed and as-run points, the line between them.

    Observations with one stamp (several tags in one image) share one row per entity, so the viewer
    shows all of them at that time (a later row at the same time would hide the earlier ones).
    """
    import rerun as rr

    obs = result.observations
    if len(obs) == 0:
        return
    plane = result.frames.camera + IMAGE_PLANE_SUFFIX

    def send(entity: str, sel: IntArray, columns: Callable[[IntArray], rr.ComponentColumnList]) -> None:
        if sel.size == 0:
            return
        rec.log(entity, rr.CoordinateFrame(plane), static=True)
        send_per_stamp(rec, entity, result, sel, columns)
        rows[entity] = int(sel.size)

    radius = np.float32(max(2.0, float(np.nanmax(overlay.width, initial=320)) / 160.0))
    corners = np.flatnonzero(np.isfinite(overlay.corners_px).all(axis=(1, 2)))
    send("/camera/overlay/corners", corners, lambda sel: rr.LineStrips2D.columns(
        strips=[np.vstack([q, q[:1]]) for q in overlay.corners_px[sel]],
        colors=np.tile(np.array(DETECTION_COLOR, dtype=np.uint8), (sel.size, 1)),
        radii=np.full(sel.size, radius / 2, dtype=np.float32)))
    def points(uv: FloatArray, color: tuple[int, int, int], what: str) -> Callable[[IntArray], rr.ComponentColumnList]:
        def columns(sel: IntArray) -> rr.ComponentColumnList:
            return rr.Points2D.columns(
                positions=uv[sel], colors=np.tile(np.array(color, dtype=np.uint8), (sel.size, 1)),
                radii=np.full(sel.size, radius * 1.5, dtype=np.float32), labels=[what] * sel.size,
                show_labels=[False] * sel.size)

        return columns

    for name, uv, color in (("recomputed", overlay.recomputed_uv, RECOMPUTED_COLOR),
                            ("as_run", overlay.as_run_uv, AS_RUN_COLOR)):
        have = np.flatnonzero(np.isfinite(uv).all(axis=1))
        what = "recomputed world point" if name == "recomputed" else f"as-run {overlay.as_run_role} point"
        send(f"/camera/overlay/{name}", have, points(uv, color, what))
    both = np.flatnonzero(np.isfinite(overlay.recomputed_uv).all(axis=1) & np.isfinite(overlay.as_run_uv).all(axis=1))
    error_px = overlay.error_px
    send("/camera/overlay/error", both, lambda sel: rr.LineStrips2D.columns(
        strips=[np.stack([overlay.recomputed_uv[i], overlay.as_run_uv[i]]) for i in sel.tolist()],
        colors=np.tile(np.array(overlay.color, dtype=np.uint8), (sel.size, 1)),
        radii=np.full(sel.size, radius / 2, dtype=np.float32),
        labels=[f"{error_px[i]:.0f} px: {overlay.label()}" for i in sel.tolist()]))
    if both.size:
        entity = "/series/error_px/as_run"
        rec.log(entity, rr.SeriesLines(names=["as-run vs recomputed in the image (px)"], colors=[overlay.color]),
                static=True)
        rec.send_columns(entity, indexes=obs_indexes(result, both),
                         columns=rr.Scalars.columns(scalars=error_px[both]))
        rows[entity] = int(both.size)


def log_depth(
    rec: rr.RecordingStream, timeline: Timeline, result: ReplayResult, opts: RerunOptions, plane: str,
    rows: dict[str, int],
) -> None:
    """Depth frames of the chain camera near observations, decimated to ``max_images``.

    Logged as uint16 millimetres (``meter=1000``): a VGA frame is 0.6 MB, so the default cap of 30
    keeps a recording under about 20 MB; lazily decoded frames cost about 70 ms each from an MCAP.
    """
    import rerun as rr

    depth = timeline.depth_frames
    mine = np.flatnonzero(depth.frame == normalize_frame(result.frames.camera))
    obs = result.observations
    if mine.size == 0 or len(obs) == 0 or opts.max_images <= 0 or depth.loader is None:
        return
    mine = mine[np.argsort(depth.stamp_ns[mine], kind="stable")]
    stamps = depth.stamp_ns[mine]
    # The frame each observation used (or the nearest within the window when depth came with it).
    want = np.where(result.depth_stamp_ns > 0, result.depth_stamp_ns, obs.stamp_ns)
    pick = nearest(stamps, want)
    near = np.abs(stamps[pick] - want) <= opts.image_window_ns
    chosen = np.unique(mine[pick[near]])
    if chosen.size > opts.max_images:
        chosen = chosen[np.linspace(0, chosen.size - 1, opts.max_images).round().astype(np.int64)]
        chosen = np.unique(chosen)
    images = [_depth_mm(depth.load(int(i))) for i in chosen]
    formats = [rr.components.ImageFormat(width=im.shape[1], height=im.shape[0], channel_datatype="U16")
               for im in images]
    rec.log("/camera/depth", rr.CoordinateFrame(plane), static=True)
    rec.send_columns(
        "/camera/depth",
        indexes=[stamp_column(SENSOR_TIME, depth.stamp_ns[chosen]),
                 stamp_column(LOG_TIME, depth.log_time_ns[chosen])],
        columns=rr.DepthImage.columns(buffer=[im.tobytes() for im in images], format=formats,
                                      meter=np.full(chosen.size, 1000.0, dtype=np.float32)),
    )
    rows["/camera/depth"] = int(chosen.size)


def _depth_mm(image_m: npt.NDArray[np.float32]) -> npt.NDArray[np.uint16]:
    """Depth in metres as uint16 millimetres (half the bytes of float32); 0 where there is none."""
    mm = np.asarray(image_m, dtype=np.float64) * 1000.0
    valid = np.isfinite(mm) & (mm > 0) & (mm < 65535.5)
    return np.ascontiguousarray(np.where(valid, np.rint(mm), 0).astype(np.uint16))
