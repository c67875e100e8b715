"""One colour legend for every output: the Rerun recording, the report's plots and image crops, and the
Foxglove export. A colour means the same thing wherever it is drawn:

- green: the detection, as the detector logged it (its centre and a tag's corners); light green: the
  pixel framechain used for it (for a tag with a size, the tag centre it estimated from the corners);
- blue: the recomputed point (the log replayed through the chain);
- orange: the as-run point (what the robot logged, or the chain as declared);
- purple: the corrected point (the findings applied);
- cyan: reference truth;
- red: an error (a rejected observation, an error not explained by a finding); light red: stale (the
  replay used a transform sample outside the latency budget);
- the line between a recomputed and an as-run point in an image: the colour of the fault that explains
  it (:data:`FAULT_COLORS`), red when no finding does.

Per-hop series (the error or time gap of each hop) take :data:`HOP_COLORS`, none of the colours above.
"""

from __future__ import annotations

from framechain.catalogue import HopName

Rgb = tuple[int, int, int]

DETECTION_COLOR: Rgb = (44, 160, 44)
USED_PIXEL_COLOR: Rgb = (152, 223, 138)
RECOMPUTED_COLOR: Rgb = (31, 119, 180)
AS_RUN_COLOR: Rgb = (255, 127, 14)
CORRECTED_COLOR: Rgb = (148, 103, 189)
REFERENCE_COLOR: Rgb = (23, 190, 207)
ERROR_COLOR: Rgb = (214, 39, 40)
STALE_COLOR: Rgb = (255, 152, 150)
#: The line of an error no finding explains.
UNEXPLAINED_COLOR: Rgb = ERROR_COLOR
#: Bounds and limits drawn for scale (the bound either side of a curve's dip), not data.
BOUND_COLOR: Rgb = (127, 127, 127)

#: Colour of an error line, by the fault of the finding that explains it: none is a colour of the legend.
FAULT_COLORS: dict[str, Rgb] = {
    "latency": (255, 215, 0), "axis_flip": (0, 0, 128), "missing_rotation": (220, 0, 180),
    "rotation_error": (247, 129, 191), "depth_scale": (140, 86, 75), "intrinsics": (188, 189, 34),
    "wrong_world_frame": (0, 128, 128), "inverted_transform": (40, 40, 40),
}

#: One colour per hop for per-hop series: none is a colour of the legend.
HOP_COLORS: dict[HopName, Rgb] = {
    HopName.PIXEL_TO_CAMERA: (140, 86, 75), HopName.CAMERA_TO_BODY: (227, 119, 194),
    HopName.BODY_TO_WORLD: (188, 189, 34),
}

#: (colour, what it means), in the order the legend states them.
LEGEND: tuple[tuple[Rgb, str, str], ...] = (
    (DETECTION_COLOR, "green", "the detection as the detector logged it (its centre, a tag's corners)"),
    (USED_PIXEL_COLOR, "light green", "the pixel framechain used (for a sized tag, the centre it estimated "
     "from the corners)"),
    (RECOMPUTED_COLOR, "blue", "recomputed (the log replayed through the chain)"),
    (AS_RUN_COLOR, "orange", "as-run (what the robot logged, or the chain as declared)"),
    (CORRECTED_COLOR, "purple", "corrected (the findings applied)"),
    (REFERENCE_COLOR, "cyan", "reference truth"),
    (ERROR_COLOR, "red", "an error no finding explains, a rejected observation"),
    (STALE_COLOR, "light red", "stale (a transform sample outside the latency budget)"),
)


def hex_color(rgb: Rgb) -> str:
    """``#rrggbb`` (matplotlib, HTML)."""
    return "#{:02x}{:02x}{:02x}".format(*rgb)


#: What the legend says of the error line, after the colours.
ERROR_LINE_LEGEND = "the line between a recomputed and an as-run point: the colour of the fault that explains it " \
    "(red when none does)"


def legend_text() -> str:
    """The legend in one sentence, as the report states it."""
    return "; ".join([*(f"{name}: {meaning}" for _rgb, name, meaning in LEGEND), ERROR_LINE_LEGEND]) + "."
