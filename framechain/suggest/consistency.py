"""Names that disagree before any number is fitted: a calibration file whose camera names another topic
than the chain's, and detections whose header.frame_id names another camera's topics.

A Kalibr camchain (TagSLAM's ``cameras.yaml``) says which topics each camera's images (``rostopic``) and
tags (``tagtopic``) are on; when the chain takes a camera for detections of another topic, every fit
that follows measures the wrong lens (a few degrees of "rotation error"). Topic names are the reliable
key: some drivers stamp the detections of one camera with another camera's frame (TagSLAM's quad rig).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from framechain.adapters.messages.kinds import normalize_msgtype
from framechain.adapters.model import LoadedLog
from framechain.config.chain import ChainConfig
from framechain.config.chain_cameras import CalibrationSource
from framechain.suggest.facts import DETECTION_TYPES, HINT_FILE_MAX_BYTES
from framechain.timeline import LogInfo


def calibration_disagreements(chain: ChainConfig, info: LogInfo | None = None) -> list[str]:
    """One line per calibration entry whose camera, by its camchain's ``tagtopic`` or ``rostopic``, belongs
    to another topic than the one the chain reads for that camera (the detections, or the images). With the
    log's ``info``, a chain topic the log lacks is left to the line that says so."""
    in_log = None if info is None else {t.name for t in getattr(info, "topics", ())}
    out = []
    for entry in chain.calibration:
        frame = entry.frame or chain.frames.camera
        if frame != chain.frames.camera:
            continue  # another camera of the chain: its topics are not named by the chain
        cameras = _kalibr_entries(chain.resolve(entry.file))
        name = _picked(cameras, entry)
        if name is None:
            continue
        picked = cameras[name]
        for key, chain_key, topic in (("tagtopic", "topics.detections", chain.topics.detections),
                                      ("rostopic", "topics.image", chain.topics.image)):
            theirs = picked.get(key)
            if not topic or not isinstance(theirs, str) or theirs == topic or (in_log is not None
                                                                                and topic not in in_log):
                continue
            owner = next((k for k, v in cameras.items() if v.get(key) == topic), None)
            fix = (f": use camera: {owner} ({Path(entry.file).name} gives {topic} to {owner})" if owner else
                   f" (no camera of {Path(entry.file).name} has {key} {topic})")
            out.append(f"calibration {Path(entry.file).name} [{name}]: its {key} is {theirs}, but the chain's "
                       f"{chain_key} is {topic}: these are another camera's intrinsics{fix}")
    return out


def _kalibr_entries(path: Path) -> dict[str, Mapping[str, Any]]:
    """The cameras of a Kalibr camchain (empty for another calibration file, or one that cannot be read: the
    reader says why)."""
    try:
        if path.stat().st_size > HINT_FILE_MAX_BYTES:
            return {}
        raw = yaml.safe_load(path.read_text(errors="replace"))
    except (OSError, yaml.YAMLError):
        return {}
    if not isinstance(raw, Mapping):
        return {}
    return {str(k): v for k, v in raw.items() if isinstance(v, Mapping) and isinstance(v.get("intrinsics"), list)}


def _picked(cameras: Mapping[str, Mapping[str, Any]], entry: CalibrationSource) -> str | None:
    """The camera the entry picks, as the calibration reader picks it (by name, else by rostopic or tagtopic)."""
    if entry.camera is None:
        return next(iter(cameras)) if len(cameras) == 1 else None
    if entry.camera in cameras:
        return entry.camera
    return next((k for k, v in cameras.items() if entry.camera in (v.get("rostopic"), v.get("tagtopic"))), None)


def frame_id_disagreements(loaded: LoadedLog) -> list[str]:
    """Detection topics whose detections' header.frame_id names another detection topic's camera
    (``/rig/top_right/tags`` stamped ``rig/bottom_left``, the namespace of ``/rig/bottom_left/tags``)."""
    topics = getattr(loaded.info, "topics", ())
    detection_topics = [t.name for t in topics if normalize_msgtype(t.msgtype) in DETECTION_TYPES]
    namespaces = {_namespace(t): t for t in detection_topics if _namespace(t)}
    obs = loaded.timeline.observations
    out = []
    for topic in detection_topics:
        frames = obs.camera_frame[obs.source == topic] if len(obs) else obs.camera_frame[:0]
        if not frames.size:
            continue
        values, counts = np.unique(frames, return_counts=True)
        frame = str(values[np.argmax(counts)])
        other = namespaces.get(frame.strip("/"))
        if other is not None and other != topic:
            out.append(f"topic {topic}: its detections' header.frame_id is {frame!r}, the camera of another topic "
                       f"({other}): the driver may stamp another camera's frame; the topic is the reliable key (a "
                       "camchain's tagtopic names it): check which camera these detections come from before "
                       "naming the chain's camera frame after them")
    return out


def _namespace(topic: str) -> str:
    """``/quadruple/top_left/tags`` -> ``quadruple/top_left``."""
    return topic.strip("/").rpartition("/")[0]


__all__ = ["calibration_disagreements", "frame_id_disagreements"]
