"""The model room: columnar tables of one log, nothing format-specific; imports nothing of framechain's other rooms."""

from framechain.timeline.columns import Column, ColumnTable, arrow_array, numpy_of
from framechain.timeline.errors import (
    InvalidCameraError,
    InvalidTransformError,
    TimelineError,
)
from framechain.timeline.frames import DepthFrameTable, DepthLoader, DepthWindows, ImageFrameTable, pixel_windows
from framechain.timeline.log_info import LogFormat, LogInfo, TopicInfo
from framechain.timeline.model import Timeline
from framechain.timeline.storage import read_parquet
from framechain.timeline.tables import (
    CameraTable,
    EgoMotionTable,
    JointStateTable,
    ObservationTable,
    PointRole,
    PointTable,
    TransformTable,
    TranslationPrior,
    format_stamp,
    normalize_frame,
    normalize_frames,
)

__all__ = [
    "CameraTable",
    "Column",
    "ColumnTable",
    "DepthFrameTable",
    "DepthLoader",
    "DepthWindows",
    "EgoMotionTable",
    "ImageFrameTable",
    "InvalidCameraError",
    "InvalidTransformError",
    "JointStateTable",
    "LogFormat",
    "LogInfo",
    "ObservationTable",
    "PointRole",
    "PointTable",
    "Timeline",
    "TimelineError",
    "TopicInfo",
    "TransformTable",
    "TranslationPrior",
    "arrow_array",
    "format_stamp",
    "normalize_frame",
    "normalize_frames",
    "numpy_of",
    "pixel_windows",
    "read_parquet",
]
