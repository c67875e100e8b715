"""What a saved recording shows, read back with Rerun's own reader: its chunks and their columns by entity, the views
of its blueprint store (class, name, origin, the entities they query), the entities that hold data, and the labels
drawn in 3D."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

#: A saved recording's chunks by entity path: (static or not, the chunk as a record batch).
Chunks = dict[str, list[tuple[bool, pa.RecordBatch]]]
#: Archetypes that draw something or say something (a pinhole, a coordinate frame or a series' style alone do not).
DATA_ARCHETYPES = frozenset({
    "Transform3D", "Points3D", "Points2D", "Arrows3D", "LineStrips3D", "LineStrips2D", "Image", "EncodedImage",
    "DepthImage", "VideoFrameReference", "Scalars", "TextLog", "TextDocument", "BarChart",
})
#: Archetypes drawn in a 3D view.
SPATIAL_3D = frozenset({"Points3D", "Arrows3D", "LineStrips3D", "TransformAxes3D"})


@dataclass(frozen=True)
class View:
    kind: str  # "3D", "2D", "TimeSeries", "TextDocument", ...
    name: str
    origin: str
    queries: tuple[str, ...]

    def shows(self, entity: str) -> bool:
        """Whether the view's contents include ``entity`` (Rerun's query rules: the last matching rule wins)."""
        included = False
        for query in self.queries or ("+ $origin/**",):
            sign, _, pattern = query.partition(" ") if query[:2] in ("+ ", "- ") else ("+", " ", query)
            pattern = pattern.replace("$origin", self.origin.rstrip("/") or "")
            if pattern.endswith("/**"):
                root = pattern[:-3]
                hit = entity == (root or "/") or entity.startswith(root + "/")
            else:
                hit = entity == pattern
            if hit:
                included = sign == "+"
        return included


def blueprint_views(rrd: Path) -> list[View]:
    from rerun.chunk import RrdReader

    reader = RrdReader(rrd)
    fields: dict[str, dict[str, Any]] = defaultdict(dict)
    for store in reader.blueprints():
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            for name in batch.schema.names:
                if ":" in name:
                    fields[str(chunk.entity_path)][name] = batch.column(name).to_pylist()[-1]
    views = []
    for path, values in fields.items():
        if "ViewBlueprint:class_identifier" not in values:
            continue
        queries = fields.get(f"{path}/ViewContents", {}).get("ViewContents:query") or []
        views.append(View(values["ViewBlueprint:class_identifier"][0], values["ViewBlueprint:display_name"][0],
                          values["ViewBlueprint:space_origin"][0], tuple(queries)))
    return views


def _archetypes(chunk: Any) -> set[str]:
    return {name.split(":", 1)[0] for name in chunk.to_record_batch().schema.names if ":" in name}


def data_entities(rrd: Path) -> set[str]:
    """Entities with a row of something shown (temporal rows, or static text, bars, transforms, points ...)."""
    from rerun.chunk import RrdReader

    return {str(chunk.entity_path) for chunk in RrdReader(rrd).stream()
            if chunk.num_rows and _archetypes(chunk) & DATA_ARCHETYPES}


def views_without_data(rrd: Path) -> list[str]:
    """The views (by name) whose contents include no entity holding data."""
    entities = data_entities(rrd)
    return [view.name for view in blueprint_views(rrd) if not any(view.shows(e) for e in entities)]


def labels_in_3d(rrd: Path) -> list[str]:
    """Every label a 3D view draws: frames' names (``TransformAxes3D`` with ``show_frame``) and the labels of
    points, arrows and lines that are shown (not hover-only)."""
    from rerun.chunk import RrdReader

    labels: list[str] = []
    for chunk in RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if not _archetypes(chunk) & SPATIAL_3D:
            continue
        if "TransformAxes3D:show_frame" in names and "CoordinateFrame:frame" in names:
            for shown, frame in zip(batch.column("TransformAxes3D:show_frame").to_pylist(),
                                    batch.column("CoordinateFrame:frame").to_pylist(), strict=True):
                if shown and shown[0]:
                    labels.append(frame[0])
        for archetype in ("Points3D", "Arrows3D", "LineStrips3D"):
            if f"{archetype}:labels" not in names:
                continue
            shown = batch.column(f"{archetype}:show_labels").to_pylist() if f"{archetype}:show_labels" in names \
                else [None] * batch.num_rows
            for texts, show in zip(batch.column(f"{archetype}:labels").to_pylist(), shown, strict=True):
                if texts and not (show and not show[0]):
                    labels.extend(texts)
    return labels


def read_chunks(path: Path) -> Chunks:
    """A saved recording's chunks by entity, in the file's order."""
    from rerun.chunk import RrdReader

    out: dict[str, list[tuple[bool, pa.RecordBatch]]] = defaultdict(list)
    for chunk in RrdReader(path).stream():
        out[chunk.entity_path].append((chunk.is_static, chunk.to_record_batch()))
    return dict(out)


def column_values(chunks: Chunks, entity: str, column: str, *, static: bool | None = None) -> list[Any]:
    """Values of one column of an entity over all its chunks, in log order (by RowId)."""
    batches = [b for s, b in chunks.get(entity, []) if static is None or s == static]
    batches = [b for b in batches if column in b.schema.names]
    if not batches:
        return []
    table = pa.Table.from_batches([b.select(["rerun.controls.RowId", column]) for b in batches])
    order = np.argsort(np.asarray(table.column("rerun.controls.RowId").to_pylist(), dtype=object), kind="stable")
    values = table.column(column).to_pylist()
    return [values[i] for i in order]
