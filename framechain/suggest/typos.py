""""Did you mean": a topic the chain names that the log lacks, or a frame no transform mentions, against the
names the log has of the right kind (difflib), so that a typo is named as the cause of what follows from it."""

from __future__ import annotations

import difflib
from collections.abc import Collection, Iterable
from dataclasses import dataclass

from framechain.adapters.messages.kinds import POSE_TYPES, normalize_msgtype
from framechain.config.chain import ChainConfig
from framechain.suggest.facts import CAMERA_INFO_TYPES, DETECTION_TYPES, IMAGE_TYPES, POINT_TYPES
from framechain.timeline import LogInfo

#: Detections may also be pixels or camera-frame points in a PointStamped.
_DETECTION_LIKE = DETECTION_TYPES | POINT_TYPES


def did_you_mean(name: str, candidates: Iterable[str], *, n: int = 3) -> list[str]:
    """The candidates closest to ``name`` (difflib's ratio, best first; none below its 0.6 cutoff)."""
    pool = sorted(set(candidates) - {name})
    return difflib.get_close_matches(name, pool, n=n)


def or_list(names: Collection[str]) -> str:
    """``'a' or 'b'``."""
    return " or ".join(repr(x) for x in names)


@dataclass(frozen=True)
class MissingTopic:
    """A topic the chain names that the log does not have, the key that names it, and the log's topics of
    the right type that are close to it (or, when none is close, all of them)."""

    key: str  # topics.odometry, topics.detections, evidence.reference, ...
    topic: str
    close: tuple[str, ...]
    of_type: tuple[str, ...]  # every topic of the log of the type the key wants

    def line(self) -> str:
        """``topics.odometry /vio_node/odm is not in the log; did you mean '/vio_node/odom'?``"""
        text = f"{self.key} {self.topic} is not in the log"
        if self.close:
            return f"{text}; did you mean {or_list(self.close)}?"
        if self.of_type:
            more = f" and {len(self.of_type) - 6} more" if len(self.of_type) > 6 else ""
            shown = ", ".join(self.of_type[:6]) + more
            return f"{text} (its topics of that type: {shown})"
        return f"{text} (it has no topic of that type)"


def missing_topics(info: LogInfo | None, chain: ChainConfig) -> list[MissingTopic]:
    """Every topic ``chain`` names that the log lacks, with the log's close topics of the wanted type."""
    if info is None:
        return []
    types = {t.name: normalize_msgtype(t.msgtype) for t in getattr(info, "topics", ())}
    t = chain.topics
    wanted: list[tuple[str, str | None, frozenset[str]]] = [
        ("topics.detections", t.detections, _DETECTION_LIKE),
        ("topics.pixel_points", t.pixel_points, POINT_TYPES),
        ("topics.camera_info", t.camera_info, CAMERA_INFO_TYPES),
        ("topics.depth", t.depth, IMAGE_TYPES),
        ("topics.image", t.image, IMAGE_TYPES),
        *(("topics.odometry", p.topic, POSE_TYPES) for p in chain.pose_topics()),
        *((f"evidence.{role.replace('hop_', 'hops.')}", topic, POINT_TYPES)
          for topic, role in chain.evidence_topics().items()),
    ]
    out = []
    for key, topic, kinds in wanted:
        if not topic or topic in types:
            continue
        of_type = sorted(name for name, msgtype in types.items() if msgtype in kinds)
        close = did_you_mean(topic, of_type) or did_you_mean(topic, types)
        out.append(MissingTopic(key, topic, tuple(close), tuple(of_type)))
    return out


__all__ = ["MissingTopic", "did_you_mean", "missing_topics", "or_list"]
