"""Matplotlib figures (Agg backend, files only)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from framechain.analysis.lab import TiltRow


def plot_tilt(rows: Sequence[TiltRow], path: str | Path, *, tolerance_m: float = 0.01) -> None:
    """Error against pitch, one line per depth, with the gripper tolerance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4), dpi=110)
    for depth in sorted({r.depth_m for r in rows}):
        sel = sorted((r for r in rows if r.depth_m == depth), key=lambda r: r.pitch_deg)
        ax.plot([r.pitch_deg for r in sel], [r.error_m * 1e3 for r in sel], label=f"Z = {depth:g} m")
    ax.axhline(tolerance_m * 1e3, color="k", ls="--", lw=1, label=f"tolerance {tolerance_m * 1e3:g} mm")
    ax.set_xlabel("camera pitch lost from the extrinsic (deg)")
    ax.set_ylabel("world-frame error (mm)")
    ax.set_yscale("symlog", linthresh=1.0)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
