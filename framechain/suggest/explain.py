"""Why a replay has nothing to show, in one line that names the chain key to add: the replay's typed
summary of its rejections (:class:`~framechain.catalogue.NothingReplayed`) read against what the chain
needs (:func:`~framechain.suggest.needs.chain_needs`)."""

from __future__ import annotations

from framechain.adapters.model import LoadedLog
from framechain.catalogue import NothingReplayed, RejectReason
from framechain.config.chain import ChainConfig
from framechain.suggest.needs import NeedStatus, chain_needs, lost_videos, quote_key

#: What to add for a reason of the replay's, when what the chain needs does not say it more precisely.
_ADD: dict[RejectReason, str] = {
    RejectReason.NO_CAMERA_INFO: "calibration: {file: CAMERAS.yaml, camera: NAME}; or topics.camera_info: TOPIC",
    RejectReason.OUTSIDE_IMAGE: "calibration: {file: CAMERAS.yaml, camera: NAME}  (the intrinsics of this image size: "
                                "the pixels fall outside the image)",
    RejectReason.NO_DEPTH: "topics.depth: DEPTH_IMAGE_TOPIC; or evidence.tag_size_m: TAG_EDGE_M",
    RejectReason.DEPTH_INVALID: "topics.depth: DEPTH_IMAGE_TOPIC  (a depth image with valid pixels at the detections)",
    RejectReason.MISSING_EDGE: "mounts: [{parent: BODY, child: CAMERA, xyz: [X, Y, Z], quat_xyzw: [QX, QY, QZ, QW]}]; "
                               "or urdf: ROBOT.urdf; or topics.odometry: POSE_TOPIC",
}
#: What to do for the reasons no chain key fixes.
_DO: dict[RejectReason, str] = {
    RejectReason.IGNORED_LABEL: "every detection's label is in `evidence.ignore_labels`: keep the static ones out "
                                "of it",
    RejectReason.EXTRAPOLATION: "check the stamps: the transforms do not cover the detections' stamps (another clock? "
                                "`framechain info` notes say)",
}
#: The pieces of the chain (:func:`chain_needs`) a reason points to: the first one missing names the key.
_PIECES: dict[RejectReason, tuple[str, ...]] = {
    RejectReason.NO_CAMERA_INFO: ("intrinsics",), RejectReason.OUTSIDE_IMAGE: ("intrinsics",),
    RejectReason.NO_DEPTH: ("depth",), RejectReason.DEPTH_INVALID: ("depth",),
    RejectReason.MISSING_EDGE: ("mount", "pose"),
}


def why_nothing_replayed(loaded: LoadedLog, chain: ChainConfig, nothing: NothingReplayed) -> str:
    """One line: why no observation was replayed (the replay's rejections, most first) and what to add."""
    needs = {n.piece: n for n in chain_needs(loaded, chain)}
    if nothing.total == 0:
        det = needs["detections"]
        if det.found:
            return f"0 observations: {det.detail}, but none reached the replay"
        if det.status is NeedStatus.MISSING and lost_videos(loaded.timeline.metadata):
            # The video is what was meant to be measured: restoring it comes before adding detections.
            return f"0 observations: {det.detail}: restore it, or {det.fix()}"
        return f"0 observations: {det.detail}: {det.fix()}"
    ranked = nothing.ranked()
    listed = ", ".join(f"{reason} {n}" for reason, n in ranked)
    top = nothing.top
    fix = "see `framechain info LOG --chain CHAIN.yaml`"
    if isinstance(top, RejectReason):
        fix = f"add {quote_key(_ADD[top])}" if top in _ADD else _DO.get(top, fix)
        if top is RejectReason.OTHER_CAMERA:
            frames = {str(f) for f in loaded.timeline.observations.camera_frame.tolist()}
            theirs = sorted(frames - {chain.frames.camera})
            fix = f"set `frames.camera` to the detections' frame ({', '.join(theirs) or 'their header.frame_id'})"
        piece = next((p for p in _PIECES.get(top, ()) if not needs[p].found), None)
        if piece is not None and needs[piece].key:
            fix = needs[piece].fix()
    source = needs["detections"].detail.split(":", 1)[0]
    return f"0 of {nothing.total} observations replayed ({source}); all rejected: {listed}: {fix}"


__all__ = ["why_nothing_replayed"]
