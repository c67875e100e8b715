"""A rig's topics and the camera each belongs to: the chain names each camera's topics, and a message on one of
them is that camera's whatever its header.frame_id says."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping

__all__ = ["TopicCameras"]


class TopicCameras:
    """The camera frame of each topic the chain gives a rig camera, and the header frames set aside for it."""

    def __init__(self, topic_frames: Mapping[str, str]) -> None:
        self.topic_frames = dict(topic_frames)
        self.relabelled: Counter[tuple[str, str, str]] = Counter()  # (topic, header frame, camera frame)

    def __bool__(self) -> bool:
        return bool(self.topic_frames)

    def frame(self, topic: str, frame: str) -> str:
        """The frame of a message: its rig camera's when the chain names its topic, else its header's."""
        mine = self.topic_frames.get(topic)
        if mine is None:
            return frame
        if frame.lstrip("/") != mine:
            self.relabelled[(topic, frame, mine)] += 1
        return mine

    def notes(self) -> list[str]:
        """One note per topic and header frame set aside for the camera the chain gives the topic."""
        return [f"topic {topic}: header.frame_id {frame!r} on {n} detections (or camera models, images), but the "
                f"chain gives this topic to camera {mine!r}: they are that camera's"
                for (topic, frame, mine), n in sorted(self.relabelled.items())]
