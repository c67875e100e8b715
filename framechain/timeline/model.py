"""The Timeline: everything one log holds that the chain needs, as columnar tables."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from framechain.timeline.columns import ColumnTable
from framechain.timeline.frames import DepthFrameTable, ImageFrameTable
from framechain.timeline.storage import read_tables, write_tables
from framechain.timeline.tables import (
    CameraTable,
    JointStateTable,
    ObservationTable,
    PointTable,
    TransformTable,
)

TABLE_TYPES: Mapping[str, type[ColumnTable]] = {
    "transforms": TransformTable,
    "cameras": CameraTable,
    "observations": ObservationTable,
    "joint_states": JointStateTable,
    "points": PointTable,
    "depth_frames": DepthFrameTable,
    "image_frames": ImageFrameTable,
}


@dataclass(frozen=True)
class Timeline:
    """Everything one log holds that the chain needs, as columnar tables.

    ``metadata`` is JSON-serialisable: source path and format, the log's time span, robot
    descriptions (URDF text by topic), adapter notes.
    """

    transforms: TransformTable = field(default_factory=TransformTable.empty)
    cameras: CameraTable = field(default_factory=CameraTable.empty)
    observations: ObservationTable = field(default_factory=ObservationTable.empty)
    joint_states: JointStateTable = field(default_factory=JointStateTable.empty)
    points: PointTable = field(default_factory=PointTable.empty)
    depth_frames: DepthFrameTable = field(default_factory=DepthFrameTable.empty)
    image_frames: ImageFrameTable = field(default_factory=ImageFrameTable.empty)
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def replace(self, **changes: Any) -> Timeline:
        """A copy with some tables (or metadata) replaced."""
        return dataclasses.replace(self, **changes)

    def save(self, directory: str | Any) -> None:
        """Write every table to ``directory/<table>.parquet`` (depth pixels included)."""
        write_tables({name: getattr(self, name) for name in TABLE_TYPES}, self.metadata, directory)

    @classmethod
    def load(cls, directory: str | Any) -> Timeline:
        """Inverse of :meth:`save`."""
        tables, metadata = read_tables(directory, TABLE_TYPES)
        return cls(**tables, metadata=metadata)

    def equals(self, other: Timeline, *, check_depth_pixels: bool = True) -> bool:
        """Exact equality of every table, the metadata and (optionally) the depth pixels."""
        for name in TABLE_TYPES:
            if not getattr(self, name).equals(getattr(other, name)):
                return False
        if dict(self.metadata) != dict(other.metadata):
            return False
        if check_depth_pixels:
            for i in range(len(self.depth_frames)):
                if not np.array_equal(self.depth_frames.load(i), other.depth_frames.load(i), equal_nan=True):
                    return False
        return True

