"""The chain configuration: which frames make the chain, which topics feed it, what evidence exists.

It is the contract of ``CHAIN.yaml``; every key is checked and unknown keys are an error that
names them::

    frames: {camera: camera_color_optical_frame, body: base_link, world: map}
    topics:
      camera_info: /camera/color/camera_info
      detections: /detections
      depth: /camera/depth/image_rect_raw
    evidence:
      hops: {camera: /debug/point_camera, body: /debug/point_body, world: /debug/point_world}
      target: /grasp_target
      reference: /mocap/target
      reference_point: [2.0, 0.5, 0.4]
      static_target: true
    latency_budget_s: 0.02
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from framechain.timeline.errors import ChainConfigError


@dataclass(frozen=True)
class ChainFrames:
    """The three frames of the chain: optical camera frame, body frame, world frame (map or odom)."""

    camera: str = "camera_optical_frame"
    body: str = "base_link"
    world: str = "map"


@dataclass(frozen=True)
class ChainTopics:
    """Where the raw inputs of the chain are recorded (None: not in this log)."""

    camera_info: str | None = None
    detections: str | None = None
    depth: str | None = None
    image: str | None = None
    #: PointStamped topic whose x, y are pixels (u, v) and z the depth in metres (0: none).
    pixel_points: str | None = None
    #: A CSV or Parquet side table of detections logged outside the bag (stamp, frame, u, v, depth).
    detections_table: str | None = None
    odometry: str | None = None


@dataclass(frozen=True)
class HopTopics:
    """Topics where the robot logged its own point at each hop (PointStamped)."""

    camera: str | None = None
    body: str | None = None
    world: str | None = None


@dataclass(frozen=True)
class ChainEvidence:
    """The evidence a log holds beyond its raw inputs (every field optional)."""

    hops: HopTopics = field(default_factory=HopTopics)
    target: str | None = None
    reference: str | None = None
    reference_point: tuple[float, float, float] | None = None
    static_target: bool = False


@dataclass(frozen=True)
class ChainConfig:
    """Frames, topics and evidence of one chain, plus the latency budget in seconds."""

    frames: ChainFrames = field(default_factory=ChainFrames)
    topics: ChainTopics = field(default_factory=ChainTopics)
    evidence: ChainEvidence = field(default_factory=ChainEvidence)
    latency_budget_s: float = 0.02
    #: Free-form robot section (URDF, joint mapping, calibrations) for joint-driven chains.
    robot: Mapping[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain dictionary, as written to CHAIN.yaml (None values dropped)."""
        out: dict[str, Any] = _drop_none(asdict(self))
        return out

    def to_yaml(self) -> str:
        """The configuration as YAML text a user can edit."""
        return yaml.safe_dump(self.to_dict(), sort_keys=False)

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any], *, where: str = "chain") -> ChainConfig:
        """Parse and check a configuration; unknown keys raise :class:`ChainConfigError`."""
        if not isinstance(raw, Mapping):
            raise ChainConfigError(f"{where}: expected a mapping at the top level")
        _check_keys(raw, cls, where)
        evidence_raw = raw.get("evidence") or {}
        _check_keys(evidence_raw, ChainEvidence, f"{where}: evidence")
        hops_raw = evidence_raw.get("hops") or {}
        _check_keys(hops_raw, HopTopics, f"{where}: evidence.hops")
        point = evidence_raw.get("reference_point")
        if point is not None:
            numbers = isinstance(point, list | tuple) and len(point) == 3 and all(
                isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in point)
            if not numbers:
                raise ChainConfigError(
                    f"{where}: evidence.reference_point must be [x, y, z], three finite numbers in metres; "
                    f"got {point!r}")
            point = tuple(float(x) for x in point)
        frames_raw = raw.get("frames") or {}
        _check_keys(frames_raw, ChainFrames, f"{where}: frames")
        topics_raw = raw.get("topics") or {}
        _check_keys(topics_raw, ChainTopics, f"{where}: topics")
        budget = raw.get("latency_budget_s", 0.02)
        if not isinstance(budget, int | float) or budget < 0:
            raise ChainConfigError(f"{where}: latency_budget_s must be a non-negative number of seconds")
        robot = raw.get("robot")
        if robot is not None and not isinstance(robot, Mapping):
            raise ChainConfigError(f"{where}: robot must be a mapping")
        frames = ChainFrames(**{k: str(v).lstrip("/") for k, v in frames_raw.items()})
        if len({frames.camera, frames.body, frames.world}) < 3:
            raise ChainConfigError(f"{where}: frames camera, body and world must be three different frames, got "
                                   f"{frames.camera!r}, {frames.body!r}, {frames.world!r}")
        return cls(
            frames=frames,
            topics=ChainTopics(**topics_raw),
            evidence=ChainEvidence(
                hops=HopTopics(**hops_raw),
                target=evidence_raw.get("target"),
                reference=evidence_raw.get("reference"),
                reference_point=point,
                static_target=bool(evidence_raw.get("static_target", False)),
            ),
            latency_budget_s=float(budget),
            robot=robot,
        )

    @classmethod
    def from_yaml(cls, path: str | Path) -> ChainConfig:
        """Read CHAIN.yaml."""
        p = Path(path)
        try:
            raw = yaml.safe_load(p.read_text())
        except OSError as err:
            raise ChainConfigError(f"{p}: cannot read chain configuration ({err.strerror})") from err
        except yaml.YAMLError as err:
            raise ChainConfigError(f"{p}: not valid YAML ({err})") from err
        if raw is None:
            raise ChainConfigError(f"{p}: the chain configuration is empty (expected frames, topics, evidence)")
        return cls.from_dict(raw, where=str(p))

    def evidence_topics(self) -> dict[str, str]:
        """Topic -> role name for every evidence topic configured."""
        out: dict[str, str] = {}
        hops = self.evidence.hops
        for role, topic in (
            ("hop_camera", hops.camera), ("hop_body", hops.body), ("hop_world", hops.world),
            ("target", self.evidence.target), ("reference", self.evidence.reference),
        ):
            if topic:
                out[topic] = role
        return out


def _check_keys(raw: Any, cls: type, where: str) -> None:
    if not isinstance(raw, Mapping):
        raise ChainConfigError(f"{where}: expected a mapping, got {type(raw).__name__}")
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise ChainConfigError(f"{where}: unknown keys {unknown}; known keys are {sorted(known)}")


def _drop_none(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _drop_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, tuple):
        return list(value)
    return value
