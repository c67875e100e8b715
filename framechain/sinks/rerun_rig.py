"""A rig in a Rerun recording: where its cameras disagree, drawn as lines between the two cameras' points."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from framechain.analysis.evidence.rig_layout import RigLayout
from framechain.arrays import rows_of
from framechain.replay import ReplayResult
from framechain.sinks.colors import ERROR_COLOR
from framechain.sinks.rerun_common import Clock, RerunOptions, entity_part, send_per_stamp

if TYPE_CHECKING:
    import rerun as rr

#: Entity of the lines between two cameras' sightings of one label at one instant.
DISAGREEMENT_ENTITY = "/points/rig/disagreement"
#: Series of the distance between two cameras' sightings, one per camera: ``/series/rig/<frame>``.
SERIES_ROOT = "/series/rig"


def log_rig(rec: rr.RecordingStream, result: ReplayResult, clock: Clock, layout: RigLayout, opts: RerunOptions,
            rows: dict[str, int]) -> None:
    """One line per same-instant comparison, from the observation's recomputed point to the other camera's point
    at that instant (in the world frame, the rig's frame without a pose), labelled with both cameras and the
    distance; at the observation's time."""
    import rerun as rr

    lines = layout.lines
    if lines is None or len(lines) == 0:
        return
    row = rows_of(result.observations.obs_id, lines.obs_id)
    have = np.flatnonzero((row >= 0) & np.isfinite(result.p_world[np.maximum(row, 0)]).all(axis=1))
    if have.size == 0:
        return
    start = np.full((len(result.observations), 3), np.nan)
    end = np.full_like(start, np.nan)
    text: dict[int, str] = {}
    obs = result.observations
    for i in have.tolist():  # one comparison per observation row is drawn (the first)
        r = int(row[i])
        if r in text:
            continue
        start[r], end[r] = result.p_world[r], lines.partner_point[i]
        gap_mm = float(np.linalg.norm(end[r] - start[r])) * 1e3
        text[r] = f"{obs.camera_frame[r]} vs {lines.partner_frame[i]}: {gap_mm:.0f} mm (label {obs.label[r]})"
    sel = np.asarray(sorted(text), dtype=np.int64)
    rec.log(DISAGREEMENT_ENTITY, rr.CoordinateFrame(result.frames.world), static=True)
    send_per_stamp(rec, DISAGREEMENT_ENTITY, result, clock, sel, lambda s: rr.LineStrips3D.columns(
        strips=[np.stack([start[i], end[i]]) for i in s.tolist()],
        colors=np.tile(np.array(ERROR_COLOR, dtype=np.uint8), (s.size, 1)),
        radii=np.full(s.size, opts.point_radius_m / 3, dtype=np.float32),
        # on hover: the 3D view's labels name the chain's frames alone
        labels=[text[i] for i in s.tolist()], show_labels=[False] * s.size))
    rows[DISAGREEMENT_ENTITY] = int(sel.size)
    gap_mm = np.linalg.norm(end - start, axis=1) * 1e3
    for frame in layout.frames:
        mine = sel[obs.camera_frame[sel] == frame]
        if mine.size == 0:
            continue
        entity = f"{SERIES_ROOT}/{entity_part(frame)}"
        rec.log(entity, rr.SeriesPoints(names=[f"{frame} vs another camera (mm)"], marker_sizes=[2.0]), static=True)
        rec.send_columns(entity, indexes=clock.obs_indexes(result, mine),
                         columns=rr.Scalars.columns(scalars=gap_mm[mine]))
        rows[entity] = int(mine.size)


__all__ = ["DISAGREEMENT_ENTITY", "SERIES_ROOT", "log_rig"]
