"""The model room: columnar tables of one log, nothing format-specific; imports nothing else here."""

from framechain.timeline.chain import ChainConfig, ChainEvidence, ChainFrames, ChainTopics, HopTopics
from framechain.timeline.conventions import OPTICAL_FROM_LINK_QUAT_XYZW
from framechain.timeline.errors import (
    ChainConfigError,
    FramechainError,
    InvalidCameraError,
    InvalidTransformError,
    TimelineError,
)
from framechain.timeline.tables import (
    CameraTable,
    Column,
    ColumnTable,
    DepthFrameTable,
    DepthLoader,
    ImageFrameTable,
    JointStateTable,
    ObservationTable,
    PointRole,
    PointTable,
    Timeline,
    TransformTable,
    format_stamp,
    normalize_frame,
    normalize_frames,
)

__all__ = [
    "OPTICAL_FROM_LINK_QUAT_XYZW",
    "CameraTable",
    "ChainConfig",
    "ChainConfigError",
    "ChainEvidence",
    "ChainFrames",
    "ChainTopics",
    "Column",
    "ColumnTable",
    "DepthFrameTable",
    "DepthLoader",
    "FramechainError",
    "HopTopics",
    "ImageFrameTable",
    "InvalidCameraError",
    "InvalidTransformError",
    "JointStateTable",
    "ObservationTable",
    "PointRole",
    "PointTable",
    "Timeline",
    "TimelineError",
    "TransformTable",
    "format_stamp",
    "normalize_frame",
    "normalize_frames",
]
