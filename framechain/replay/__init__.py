"""The replay room: TransformBuffer (tf2 semantics, vectorised), the hop-by-hop replay (the camera model is
:mod:`framechain.geometry.camera`)."""

from framechain.replay.buffer import (
    LATEST,
    Edge,
    FramePath,
    HopSamples,
    LookupResult,
    LookupStatus,
    PathHop,
    TransformBuffer,
)
from framechain.replay.depth import DepthSamples, sample_depth
from framechain.replay.errors import (
    ConnectivityError,
    ExtrapolationError,
    FrameGraphError,
    TransformLookupError,
)
from framechain.replay.replay import (
    REPLAYED,
    HopRecordTable,
    HopSampleTable,
    ReplayOptions,
    ReplayResult,
    camera_rows_for,
    replay,
)

__all__ = [
    "LATEST",
    "REPLAYED",
    "ConnectivityError",
    "DepthSamples",
    "Edge",
    "ExtrapolationError",
    "FrameGraphError",
    "FramePath",
    "HopRecordTable",
    "HopSampleTable",
    "HopSamples",
    "LookupResult",
    "LookupStatus",
    "PathHop",
    "ReplayOptions",
    "ReplayResult",
    "TransformBuffer",
    "TransformLookupError",
    "camera_rows_for",
    "replay",
    "sample_depth",
]
