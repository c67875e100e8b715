"""What a number a user writes can physically be: the unit slips worth one line each.

Each check takes a value already known to be a finite number (or vector) of the right type and
either returns None (plausible), returns a note (plausible but unusual: the configuration carries
it and the outputs show it), or raises :class:`Implausible` naming the likely slip. The texts
continue a key path: ``evidence.tag_size_m`` + ``" is 160 m, ..."``. The thresholds (error; note):

- tag or marker side: over 3 m (millimetres or centimetres written as metres) or under 3 mm; over
  1 m or under 1 cm;
- angles (rpy, rotvec): any angle over 2 pi (degrees written as radians); an angle over pi;
- mount translation: over 10 m from its parent (millimetres or centimetres as metres); over 3 m;
- world position (reference point, world_from_base): over 100 km from the origin;
- latency_budget_s: over 5 s (milliseconds as seconds); over 1 s;
- tolerance_m (the error worth acting on): over 1 m (millimetres as metres); over 10 cm;
- static_window_s: under 10 ms, over an hour (milliseconds as seconds); over 10 minutes;
- camera_offset_window_s (how far a camera's offset is searched from its motion): under 50 ms (a few of
  its 10 ms steps), over 60 s (milliseconds as seconds); over 5 s;
- intrinsics: cx or cy outside the image; fx or fy under width / 20 (a field of view over 170
  degrees, or K normalised by the image size) or over width x 50; fx and fy 10 % apart;
- depth scale_m (metres per unit): over 10 (units per metre), under 1e-6; not 1 and outside
  1e-4 ... 1e-2;
- a camera's clock offset_s: over an hour; over a second;
- joint offsets and held positions: over 2 pi (degrees as radians).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

#: Tag or marker side (m): outside [TAG_MIN_M, TAG_MAX_M] is an error, outside the note bounds a note.
TAG_MIN_M, TAG_NOTE_MIN_M, TAG_NOTE_MAX_M, TAG_MAX_M = 0.003, 0.01, 1.0, 3.0
#: A mount farther from its parent than this is an error (m); farther than the note bound, a note.
MOUNT_MAX_M, MOUNT_NOTE_M = 10.0, 3.0
#: A world position (reference point, world_from_base) farther than this from the origin (m).
POSITION_MAX_M = 1e5
#: A latency budget (s) above this is an error, above the note bound a note.
BUDGET_MAX_S, BUDGET_NOTE_S = 5.0, 1.0
#: The practical tolerance (m): above the first an error (millimetres as metres), above the second a note.
TOLERANCE_MAX_M, TOLERANCE_NOTE_M = 1.0, 0.1
#: Static-target windows (s).
WINDOW_MIN_S, WINDOW_NOTE_S, WINDOW_MAX_S = 0.01, 600.0, 3600.0
#: Focal length in pixels against the image width: below the first (a horizontal field of view
#: over 170 degrees for a pinhole, or K normalised by the image size) or above the second (under
#: 1.2 degrees) is an error.
FOCAL_MIN_PER_WIDTH, FOCAL_MAX_PER_WIDTH = 0.05, 50.0
#: Depth unit (metres per unit) bounds and the usual values (m, mm, 0.1 mm).
DEPTH_SCALE_MIN, DEPTH_SCALE_MAX = 1e-6, 10.0
#: A camera's clock offset (s).
CAMERA_OFFSET_MAX_S, CAMERA_OFFSET_NOTE_S = 3600.0, 1.0
#: The window a camera's offset is searched over from its motion (s, either way).
OFFSET_WINDOW_MIN_S, OFFSET_WINDOW_NOTE_S, OFFSET_WINDOW_MAX_S = 0.05, 5.0, 60.0


class Implausible(ValueError):  # noqa: N818 - a verdict, raised where a value is read
    """A value that cannot be what its key means; the text continues the key's path."""


def _g(value: float) -> str:
    return f"{value:.6g}"


def _smaller_unit(value: float, unit: str, limit: float) -> str:
    """``160 mm is 0.16 m``: the value read in the unit a thousand (or a hundred) times smaller, when
    that reading is below ``limit``."""
    if abs(value) / 1000 > limit:
        return f"give {unit}s"
    if abs(value) >= 100:
        return f"it looks like milli{unit}s ({_g(value)} m{unit[0]} is {_g(value / 1000)} {unit[0]})"
    return (f"it looks like centi{unit}s or milli{unit}s ({_g(value)} c{unit[0]} is {_g(value / 100)} {unit[0]}, "
            f"{_g(value)} m{unit[0]} is {_g(value / 1000)} {unit[0]})")


def tag_size(size_m: float) -> str | None:
    """The side of a square tag or marker, in metres."""
    if size_m > TAG_MAX_M:
        raise Implausible(f"is {_g(size_m)} m, too large for a tag: {_smaller_unit(size_m, 'metre', TAG_MAX_M)}")
    if size_m < TAG_MIN_M:
        raise Implausible(f"is {_g(size_m)} m, too small for a tag (under {TAG_MIN_M * 1e3:g} mm): give the side "
                          "of the black square in metres (a 16 cm tag is 0.16)")
    if size_m > TAG_NOTE_MAX_M:
        return f"is {_g(size_m)} m: a tag over {TAG_NOTE_MAX_M:g} m is unusual (is the side in metres?)"
    if size_m < TAG_NOTE_MIN_M:
        return f"is {_g(size_m)} m: a tag under {TAG_NOTE_MIN_M * 100:g} cm is unusual (is the side in metres?)"
    return None


def angles(values: Sequence[float], kind: str) -> str | None:
    """Angles in radians: roll-pitch-yaw (``kind`` "rpy") or a rotation vector ("rotvec")."""
    listed = "[" + ", ".join(_g(v) for v in values) + "]"
    sizes = [abs(v) for v in values] if kind == "rpy" else [math.hypot(*values)]
    worst = max(sizes)
    what = "an angle" if kind == "rpy" else "a rotation angle"
    if worst > 2 * math.pi:
        raise Implausible(f"{listed} has {what} of {_g(worst)}, beyond 2 pi: angles are radians, and this looks like "
                          f"degrees ({_g(worst)} deg is {_g(math.radians(worst))} rad)")
    if worst > math.pi + 1e-9:
        return f"{listed} has {what} of {_g(worst)} rad, beyond pi (the same rotation as {_g(worst - 2 * math.pi)})"
    return None


def mount_translation(xyz: Sequence[float]) -> str | None:
    """A mount's translation from its parent frame, in metres."""
    distance = math.hypot(*xyz)
    if distance > MOUNT_MAX_M:
        raise Implausible(f"puts the frame {_g(distance)} m from its parent, farther than any mount on a robot "
                          f"({MOUNT_MAX_M:g} m): {_smaller_unit(distance, 'metre', MOUNT_MAX_M)}")
    if distance > MOUNT_NOTE_M:
        return f"puts the frame {_g(distance)} m from its parent: unusually far for a mount"
    return None


def position(xyz: Sequence[float]) -> None:
    """A position in a world frame, in metres."""
    distance = math.hypot(*xyz)
    if distance > POSITION_MAX_M:
        raise Implausible(f"is {_g(distance)} m from the origin, beyond {POSITION_MAX_M / 1e3:g} km: give metres")


def latency_budget(seconds: float) -> str | None:
    if seconds > BUDGET_MAX_S:
        raise Implausible(_too_long(seconds, BUDGET_MAX_S, "a latency budget"))
    if seconds > BUDGET_NOTE_S:
        return f"is {_g(seconds)} s: a budget over {BUDGET_NOTE_S:g} s lets poses that old through"
    return None


def tolerance(metres: float) -> str | None:
    """The error worth acting on (``tolerance_m``), in metres."""
    if metres > TOLERANCE_MAX_M:
        raise Implausible(f"is {_g(metres)} m, too large for the error worth acting on: "
                          f"{_smaller_unit(metres, 'metre', TOLERANCE_MAX_M)}")
    if metres > TOLERANCE_NOTE_M:
        return f"is {_g(metres)} m: findings under {_g(metres * 100)} cm are notes, not fixes"
    return None


def static_window(seconds: float) -> str | None:
    if seconds < WINDOW_MIN_S:
        raise Implausible(f"is {_g(seconds)} s, shorter than one camera frame: give seconds (5 is five seconds)")
    if seconds > WINDOW_MAX_S:
        raise Implausible(_too_long(seconds, WINDOW_MAX_S, "a static-target window"))
    if seconds > WINDOW_NOTE_S:
        return (f"is {_g(seconds)} s: windows over {WINDOW_NOTE_S / 60:g} minutes let odometry drift pose as a "
                "fault")
    return None


def _too_long(seconds: float, limit: float, what: str) -> str:
    return (f"is {_g(seconds)} s, too long for {what} (over {limit:g} s): it looks like milliseconds "
            f"({_g(seconds)} ms is {_g(seconds / 1000)} s)")


def offset_window(seconds: float) -> str | None:
    if seconds < OFFSET_WINDOW_MIN_S:
        raise Implausible(f"is {_g(seconds)} s: the search needs {_g(OFFSET_WINDOW_MIN_S)} s at least, a few of its "
                          "10 ms steps either way (give seconds: 1 is one second)")
    if seconds > OFFSET_WINDOW_MAX_S:
        raise Implausible(_too_long(seconds, OFFSET_WINDOW_MAX_S, "a camera offset search"))
    if seconds > OFFSET_WINDOW_NOTE_S:
        return (f"is {_g(seconds)} s: only the frame pairs this far from both ends of an episode are compared, and "
                "the search takes longer")
    return None


def camera_offset(seconds: float) -> str | None:
    if abs(seconds) > CAMERA_OFFSET_MAX_S:
        raise Implausible(f"is {_g(seconds)} s, over an hour: it looks like milliseconds or nanoseconds "
                          f"({_g(seconds)} ms is {_g(seconds / 1000)} s)")
    if abs(seconds) > CAMERA_OFFSET_NOTE_S:
        return f"is {_g(seconds)} s: a camera clock over {CAMERA_OFFSET_NOTE_S:g} s off is unusual"
    return None


def joint_value(value: float) -> None:
    """A joint position or offset in radians (revolute) or metres (prismatic)."""
    if abs(value) > 2 * math.pi:
        raise Implausible(f"is {_g(value)}, beyond 2 pi: joint values are radians (or metres), and this looks "
                          f"like degrees ({_g(value)} deg is {_g(math.radians(value))} rad)")


def depth_scale(scale_m: float) -> str | None:
    """Metres per unit of a depth image."""
    if scale_m > DEPTH_SCALE_MAX:
        raise Implausible(f"is {_g(scale_m)} metres per unit: it looks like units per metre (give "
                          f"{_g(1 / scale_m)})")
    if scale_m < DEPTH_SCALE_MIN:
        raise Implausible(f"is {_g(scale_m)} metres per unit, under a micrometre: give metres per unit (0.001 for "
                          "millimetres)")
    if scale_m != 1.0 and not 1e-4 <= scale_m <= 1e-2:
        return f"is {_g(scale_m)} metres per unit: unusual (metres 1, millimetres 0.001, 0.1 mm 0.0001)"
    return None


def intrinsics(fx: float, fy: float, cx: float, cy: float, width: int, height: int) -> str | None:
    """Pinhole intrinsics against the image size; the texts start with the key at fault (``cx 1280 ...``)."""
    for key, value, size, side in (("cx", cx, width, "width"), ("cy", cy, height, "height")):
        if not -0.5 <= value <= size - 0.5:
            raise Implausible(f"{key} {_g(value)} is outside the image ({side} {size} px): the intrinsics of "
                              "another resolution, or the image size of another camera")
    for key, value in (("fx", fx), ("fy", fy)):
        if value < FOCAL_MIN_PER_WIDTH * width:
            normalised = " (it looks normalised by the image size: give pixels)" if value < 10 else ""
            raise Implausible(f"{key} {_g(value)} px is too small for an image {width} px wide (a field of view over "
                              f"170 degrees){normalised}")
        if value > FOCAL_MAX_PER_WIDTH * width:
            raise Implausible(f"{key} {_g(value)} px is too large for an image {width} px wide (a field of view "
                              "under 1.2 degrees): give the focal length in pixels")
    if abs(fx - fy) > 0.1 * max(fx, fy):
        return f"fx {_g(fx)} and fy {_g(fy)} differ by more than 10 % (pixels are rarely that far from square)"
    return None
