"""One palette for every output: the Rerun recording, the report's plots and image crops, the fleet report and the
Foxglove export. A colour means the same thing wherever it is drawn, and the legend every output states is made
from this palette (:func:`legend_text`), so a colour drawn is a colour explained:

- green: the detection, as the detector logged it (its centre and a tag's corners); light green: the
  pixel framechain used for it (for a tag with a size, the tag centre it estimated from the corners);
- blue: the recomputed point (the log replayed through the chain);
- orange: the as-run point (what the robot logged, or the chain as declared);
- purple: corrected (the findings applied: points, the error left, an estimate);
- cyan: reference truth;
- grey: the error as recorded, before any finding is applied;
- light grey (dotted or dashed): what is drawn for scale, not data (a bound, the tolerance, no fault);
- red: an error no finding explains, a rejected observation; light red: stale (the replay used a transform
  sample outside the latency budget);
- a fault's colour (:data:`FAULT_COLORS`): the line between a recomputed and an as-run point it explains,
  and anything drawn of that fault alone (how far it moves the points, its estimates across a fleet);
- a hop's colour (:data:`HOP_COLORS`): that hop's own series (its error, its time gap).

No colour is in two of these groups (tests/sinks/test_viewer_truth.py checks it).
"""

from __future__ import annotations

from framechain.catalogue import Fault, HopName

Rgb = tuple[int, int, int]

DETECTION_COLOR: Rgb = (44, 160, 44)
USED_PIXEL_COLOR: Rgb = (152, 223, 138)
RECOMPUTED_COLOR: Rgb = (31, 119, 180)
AS_RUN_COLOR: Rgb = (255, 127, 14)
CORRECTED_COLOR: Rgb = (148, 103, 189)
REFERENCE_COLOR: Rgb = (23, 190, 207)
#: The error against the evidence as recorded (before the findings): the world error, the static spread, the
#: error a fault's size is varied against.
RECORDED_ERROR_COLOR: Rgb = (110, 110, 110)
#: Bounds and limits drawn for scale (the bound either side of a curve's dip, the tolerance, no fault), not data.
BOUND_COLOR: Rgb = (180, 180, 180)
ERROR_COLOR: Rgb = (214, 39, 40)
STALE_COLOR: Rgb = (255, 152, 150)
#: The line of an error no finding explains.
UNEXPLAINED_COLOR: Rgb = ERROR_COLOR

#: Colour of each fault: the line of an error it explains, and what is drawn of it alone.
FAULT_COLORS: dict[str, Rgb] = {
    Fault.LATENCY.value: (255, 215, 0), Fault.AXIS_FLIP.value: (0, 0, 128),
    Fault.MISSING_ROTATION.value: (220, 0, 180), Fault.ROTATION_ERROR.value: (247, 129, 191),
    Fault.TRANSLATION_ERROR.value: (141, 182, 0), Fault.DEPTH_SCALE.value: (140, 86, 75),
    Fault.INTRINSICS.value: (188, 189, 34), Fault.WRONG_WORLD_FRAME.value: (0, 128, 128),
    Fault.WRONG_CAMERA_FRAME.value: (194, 178, 128), Fault.INVERTED_TRANSFORM.value: (40, 40, 40),
}

#: One colour per hop for per-hop series.
HOP_COLORS: dict[HopName, Rgb] = {
    HopName.PIXEL_TO_CAMERA: (0, 95, 70), HopName.CAMERA_TO_BODY: (128, 0, 64),
    HopName.BODY_TO_WORLD: (90, 90, 20),
}

#: (colour, its name, what it means), in the order the legend states them.
LEGEND: tuple[tuple[Rgb, str, str], ...] = (
    (DETECTION_COLOR, "green", "the detection as the detector logged it (its centre, a tag's corners)"),
    (USED_PIXEL_COLOR, "light green", "the pixel framechain used (for a sized tag, the centre it estimated "
     "from the corners)"),
    (RECOMPUTED_COLOR, "blue", "recomputed (the log replayed through the chain)"),
    (AS_RUN_COLOR, "orange", "as-run (what the robot logged, or the chain as declared)"),
    (CORRECTED_COLOR, "purple", "corrected (the findings applied: points, the error left, an estimate)"),
    (REFERENCE_COLOR, "cyan", "reference truth"),
    (RECORDED_ERROR_COLOR, "grey", "the error as recorded, before any finding"),
    (BOUND_COLOR, "light grey (dotted, dashed)", "drawn for scale: a bound, the tolerance, no fault"),
    (ERROR_COLOR, "red", "an error no finding explains, a rejected observation"),
    (STALE_COLOR, "light red", "stale (a transform sample outside the latency budget)"),
)


def hex_color(rgb: Rgb) -> str:
    """``#rrggbb`` (matplotlib, HTML)."""
    return "#{:02x}{:02x}{:02x}".format(*rgb)


#: What the legend says of the fault and hop colours, before naming them.
ERROR_LINE_LEGEND = "the line between a recomputed and an as-run point takes the colour of the fault that explains " \
    "it (red when none does), as does anything drawn of that fault alone"
HOP_LEGEND = "each hop's own series takes the hop's colour"


def legend_text() -> str:
    """The legend in one paragraph, as the reports and Rerun state it (the swatches' words only)."""
    meanings = "; ".join(f"{name}: {meaning}" for _rgb, name, meaning in LEGEND)
    faults = ", ".join(f"{fault} {hex_color(rgb)}" for fault, rgb in FAULT_COLORS.items())
    hops = ", ".join(f"{hop.value} {hex_color(rgb)}" for hop, rgb in HOP_COLORS.items())
    return f"{meanings}. {ERROR_LINE_LEGEND} ({faults}); {HOP_LEGEND} ({hops})."
