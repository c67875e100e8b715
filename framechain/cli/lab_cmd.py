"""``framechain lab tilt``: the seed lab, error of a translation-only extrinsic over pitch and depth."""

from __future__ import annotations

import argparse
import json
from typing import Any


def register(sub: Any) -> None:
    lab = sub.add_parser("lab", help="labs: sensitivity sweeps that need no log")
    lab_sub = lab.add_subparsers(dest="lab", metavar="LAB", required=True)
    tilt = lab_sub.add_parser(
        "tilt",
        help="world error of a translation-only extrinsic over camera pitch and depth",
        description="Sweep camera pitch and depth; report how far a target lands when the extrinsic "
        "keeps the mount translation but loses its pitch (about depth * sin(pitch)).",
    )
    tilt.add_argument("--max-pitch", type=float, default=30.0, help="largest pitch in degrees (default 30)")
    tilt.add_argument("--step", type=float, default=1.0, help="pitch step in degrees (default 1)")
    tilt.add_argument("--depths", default="0.5,1,2", help="comma-separated depths in metres (default 0.5,1,2)")
    tilt.add_argument("--tolerance", type=float, default=0.01,
                      help="gripper tolerance in metres for the crossing pitch (default 0.01)")
    tilt.add_argument("--json", action="store_true", help="print rows of pitch_deg, depth_m, error_m as JSON")
    tilt.add_argument("--plot", metavar="PNG", help="write a plot of error against pitch")
    tilt.set_defaults(run=run_tilt)


def _depths(text: str) -> list[float]:
    from framechain.errors import FramechainError

    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError as err:
        raise FramechainError(f"--depths: expected comma-separated metres, got {text!r}") from err
    if not values or any(v <= 0 for v in values):
        raise FramechainError(f"--depths: expected positive metres, got {text!r}")
    return values


def run_tilt(args: argparse.Namespace) -> int:
    import numpy as np

    from framechain.analysis.lab import crossing_pitch_deg, tilt_sweep
    from framechain.cli.common import stdout_console
    from framechain.errors import FramechainError

    if args.max_pitch < 0 or args.max_pitch > 89 or args.step <= 0:
        raise FramechainError("--max-pitch must be within 0..89 degrees and --step positive")
    depths = _depths(args.depths)
    pitches = np.arange(0.0, args.max_pitch + 1e-9, args.step)
    rows = tilt_sweep(pitches.tolist(), depths)
    if args.plot:
        from framechain.sinks.plots import plot_tilt

        plot_tilt(rows, args.plot, tolerance_m=args.tolerance)
    if args.json:
        print(json.dumps([{"pitch_deg": r.pitch_deg, "depth_m": r.depth_m, "error_m": r.error_m} for r in rows]))
        return 0
    from rich.table import Table

    console = stdout_console()
    table = Table(title="World error of a translation-only extrinsic (mm)")
    table.add_column("pitch (deg)", justify="right")
    for d in depths:
        table.add_column(f"Z = {d:g} m", justify="right")
    by_key = {(r.pitch_deg, r.depth_m): r.error_m for r in rows}
    shown = [p for p in pitches if p in (0, 1, 2, 5, 10, 15, 20, 25, 30) or p == pitches[-1]]
    for p in shown:
        table.add_row(f"{p:g}", *[f"{by_key[(float(p), d)] * 1e3:.1f}" for d in depths])
    console.print(table)
    for d in depths:
        cross = crossing_pitch_deg(rows, d, args.tolerance)
        where = f"{cross:.2f} deg" if cross is not None else f"beyond {args.max_pitch:g} deg"
        console.print(f"At Z = {d:g} m the error passes {args.tolerance * 1e3:g} mm at a pitch of {where}.")
    if args.plot:
        console.print(f"plot: {args.plot}")
    return 0
