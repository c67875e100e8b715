"""The one way a configuration file is read: a mapping walked key by key, each value typed, checked
and checked for plausibility, each mistake one line that names the file, the key and the value.

CHAIN.yaml, robot.yaml and the calibration files are all read through :class:`Section`::

    top = Section(raw, source="chain.yaml", known={"frames", "evidence"}, error=ChainConfigError)
    evidence = top.section("evidence", known={"tag_size_m", "static_window_s"})
    window = evidence.number("static_window_s", positive=True, unit="s", check=plausible.static_window)
    # chain.yaml: evidence.static_window_s must be a positive number (s), got -1

Messages come in three shapes: a value of the wrong type or range, ``"<path> must be <what>, got
<value>"``; a structural mistake, ``"<section>: missing <key>"`` or ``"<section>: unknown keys
[...]; known keys are [...]"``; and a value that cannot be what its key means (a unit slip, see
:mod:`framechain.config.plausible`), ``"<path> is 160 m, too large for a tag: ..."``. Plausible
but unusual values become notes (``"<source>: <path> ..."``) in the list the sections share.

:meth:`Section.pose` is the one mount parser: ``xyz`` plus exactly one of ``rpy`` (radians, fixed
axes x-y-z as URDF), ``quat_xyzw`` or ``rotvec`` (radians).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import fields
from pathlib import Path
from typing import Any, NamedTuple, NoReturn

import numpy as np
import yaml

from framechain.config import plausible
from framechain.config.errors import ConfigError
from framechain.geometry.rotations import quat_from_rotvec, quat_from_rpy

__all__ = ["ROTATION_KEYS", "Pose", "Section", "as_list", "dataclass_keys", "finite_number", "read_yaml", "show"]

#: The rotation keys of a pose; exactly one may be given.
ROTATION_KEYS = ("quat_xyzw", "rpy", "rotvec")
_ROTATION_HELP = ("(rpy [roll, pitch, yaw] in radians about fixed axes x-y-z as URDF, quat_xyzw [x, y, z, w], "
                  "rotvec [x, y, z] in radians)")

#: A plausibility check of a value: returns a note or None, raises plausible.Implausible.
Check = Callable[[Any], str | None]


class Pose(NamedTuple):
    """``T_parent_child`` as read from a file: translation (m) and unit quaternion ``quat_xyzw``."""

    xyz: tuple[float, float, float]
    quat_xyzw: tuple[float, float, float, float]


def show(value: Any, limit: int = 80) -> str:
    """``repr`` of a value for a one-line message, cut to ``limit`` characters."""
    text = repr(value).replace("\n", " ")
    return text if len(text) <= limit else text[: limit - 3] + "..."


def read_yaml(path: Path, *, error: type[ConfigError], what: str, loader: type[yaml.SafeLoader] = yaml.SafeLoader,
              prepare: Callable[[str], str] | None = None) -> Any:
    """The YAML document of a file (a SafeLoader, or a subclass of it); one line naming the file when it
    cannot be read or parsed. ``prepare`` edits the text first (OpenCV's ``%YAML:1.0`` header)."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise error(str(path), f"cannot read {what} ({err.strerror or err})") from err
    except UnicodeDecodeError as err:
        raise error(str(path), f"cannot read {what}: not UTF-8 text (byte {err.start})") from err
    try:
        return yaml.load(prepare(text) if prepare else text, Loader=loader)  # the loader is a SafeLoader
    except yaml.YAMLError as err:
        raise error(str(path), f"not valid YAML ({_yaml_problem(err)})") from err
    except RecursionError as err:
        raise error(str(path), "not valid YAML (nested too deeply)") from err


def _yaml_problem(err: yaml.YAMLError) -> str:
    """PyYAML's multi-line message in one line: where, and what."""
    if isinstance(err, yaml.MarkedYAMLError) and err.problem_mark is not None:
        mark = err.problem_mark
        return f"line {mark.line + 1}, column {mark.column + 1}: {err.problem or err.context or 'unreadable'}"
    return " ".join(str(err).split())


def dataclass_keys(cls: type, *internal: str) -> set[str]:
    """The keys a file may give for a dataclass: its fields, less the ``internal`` ones."""
    return {f.name for f in fields(cls)} - set(internal)


def as_list(raw: Any) -> list[Any]:
    """A key given as one entry or a list of them, as a list (empty when not given)."""
    if raw is None:
        return []
    return list(raw) if isinstance(raw, list | tuple) else [raw]


def finite_number(value: Any) -> bool:
    """An int or float (not a bool) that is finite as a float (YAML ints may be too large for one)."""
    if not isinstance(value, int | float) or isinstance(value, bool):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


class Section:
    """One mapping of a configuration file, read key by key.

    ``source`` names the file (every message starts with it), ``where`` the path of this mapping in
    it ("" at the top, ``evidence``, ``mounts[0]``), ``known`` its keys (None: any key), ``error``
    the exception type raised, ``notes`` the list of notes the sections of one file share.
    """

    def __init__(self, raw: Any, *, source: str, where: str = "", known: Collection[str] | None = None,
                 error: type[ConfigError] = ConfigError, notes: list[str] | None = None,
                 what: str = "a mapping") -> None:
        self.source = source
        self.where = where
        self.error = error
        self.notes: list[str] = [] if notes is None else notes
        if not isinstance(raw, Mapping):
            if where:
                raise error(source, f"{where} must be {what}, got {show(raw)}")
            raise error(source, f"expected a mapping at the top level, got {type(raw).__name__}")
        self.raw: Mapping[Any, Any] = raw
        if known is not None:
            unknown = sorted(str(k) for k in raw if k not in known)
            if unknown:
                self.fail(f"unknown keys {unknown}; known keys are {sorted(known)}")

    # -- paths, errors and notes ----------------------------------------------------------------------
    def path(self, key: Any) -> str:
        """The path of ``key`` in the file: ``evidence.tag_size_m``, ``mounts[0]``."""
        return f"{self.where}.{key}" if self.where else str(key)

    def fail(self, what: str) -> NoReturn:
        """A mistake in this mapping as a whole: ``"<where>: <what>"``."""
        raise self.error(self.source, f"{self.where}: {what}" if self.where else what)

    def fail_at(self, path: str, what: str) -> NoReturn:
        """A mistake in one value: ``"<path> <what>"``."""
        raise self.error(self.source, f"{path} {what}")

    def fail_in(self, path: str, what: str) -> NoReturn:
        """A mistake among the values under ``path``: ``"<path>: <what>"``."""
        raise self.error(self.source, f"{path}: {what}")

    def expected(self, key: Any, what: str, value: Any) -> NoReturn:
        """A value of none of the shapes a key takes: ``"<path>: expected <what>, got <value>"``."""
        self.expected_at(self.path(key), what, value)

    def expected_at(self, path: str, what: str, value: Any) -> NoReturn:
        self.fail_in(path, f"expected {what}, got {show(value)}")

    def note_at(self, path: str, text: str) -> None:
        self.notes.append(f"{self.source}: {path} {text}")

    def check_plausible(self, path: str, check: Check, value: Any, *, within: bool = False) -> None:
        """Run a plausibility check: an error naming the slip, a note, or nothing. ``within``: the
        check's text names a key below ``path`` (``"<path>: cx 1280 is ..."``)."""
        path = f"{path}:" if within else path
        try:
            note = check(value)
        except plausible.Implausible as err:
            self.fail_at(path, str(err))
        if note:
            self.note_at(path, note)

    # -- keys ---------------------------------------------------------------------------------------
    def __contains__(self, key: object) -> bool:
        """Whether ``key`` is given (a key whose value is null counts as not given)."""
        return self.raw.get(key) is not None

    def get(self, key: Any, default: Any = None) -> Any:
        value = self.raw.get(key)
        return default if value is None else value

    def require(self, key: Any, hint: str = "") -> Any:
        """The value of ``key``; ``"<where>: missing <key> (<hint>)"`` when it is not given."""
        if key not in self:
            self.fail(f"missing {key}" + (f" ({hint})" if hint else ""))
        return self.raw[key]

    def entries(self) -> Iterator[tuple[str, Any]]:
        """``(key as text, value)`` of every key, in file order."""
        for key, value in self.raw.items():
            yield str(key), value

    def section(self, key: Any, known: Collection[str] | None = None, *, what: str = "a mapping") -> Section:
        """The mapping under ``key`` (an empty one when the key is not given)."""
        return Section(self.get(key, {}), source=self.source, where=self.path(key), known=known, error=self.error,
                       notes=self.notes, what=what)

    def child(self, raw: Any, where: str, known: Collection[str] | None = None, *, what: str = "a mapping") -> Section:
        """A mapping found inside a value of this one (a list entry), at ``where``."""
        return Section(raw, source=self.source, where=where, known=known, error=self.error, notes=self.notes,
                       what=what)

    # -- typed values -------------------------------------------------------------------------------
    def name(self, key: Any, default: str | None = None, *, required: bool = False, hint: str = "",
             what: str = "a name") -> str | None:
        """A name (a frame, topic, camera, file): text, or a whole number YAML read as one; stripped."""
        if required:
            self.require(key, hint)
        value = self.raw.get(key)
        if value is None:
            return default
        if isinstance(value, int) and not isinstance(value, bool):
            value = str(value)
        if not isinstance(value, str) or not value.strip():
            self.fail_at(self.path(key), f"must be {what}, got {show(value)}")
        return value.strip()

    def frame(self, key: Any, default: str | None = None, *, required: bool = False, hint: str = "") -> str | None:
        """A frame name, without the leading ``/`` tf1 used."""
        value = self.name(key, default, required=required, hint=hint, what="a frame name")
        if value is not None and not value.lstrip("/"):
            self.fail_at(self.path(key), f"must be a frame name, got {show(value)}")
        return None if value is None else value.lstrip("/")

    def flag(self, key: Any, default: bool) -> bool:
        value = self.raw.get(key)
        if value is None:
            return default
        if not isinstance(value, bool):
            self.fail_at(self.path(key), f"must be true or false, got {show(value)}")
        return value

    def number(self, key: Any, default: float | None = None, *, required: bool = False, hint: str = "",
               positive: bool = False, minimum: float | None = None, unit: str = "",
               check: Check | None = None) -> float | None:
        """A finite number (``positive``: > 0; ``minimum``: >= it), then its plausibility ``check``."""
        if required:
            self.require(key, hint)
        value = self.raw.get(key)
        if value is None:
            return default
        return self.number_value(value, self.path(key), positive=positive, minimum=minimum, unit=unit, check=check)

    def number_value(self, value: Any, path: str, *, positive: bool = False, minimum: float | None = None,
                     unit: str = "", check: Check | None = None) -> float:
        """:meth:`number` for a value found elsewhere (a list entry, a mapping of sizes), at ``path``."""
        kind = "a positive number" if positive else "a number" if minimum is None else f"a number >= {minimum:g}"
        what = f"{kind} ({unit})" if unit else kind
        ok = finite_number(value) and (not positive or value > 0) and (minimum is None or value >= minimum)
        if not ok:
            self.fail_at(path, f"must be {what}, got {show(value)}")
        if check is not None:
            self.check_plausible(path, check, float(value))
        return float(value)

    def vector(self, key: Any, n: int, default: tuple[float, ...] | None = None, *, required: bool = False,
               hint: str = "", what: str = "", check: Check | None = None) -> tuple[float, ...] | None:
        """``n`` finite numbers (a list), then their plausibility ``check``."""
        if required:
            self.require(key, hint)
        value = self.raw.get(key)
        if value is None:
            return default
        return self.vector_value(value, n, self.path(key), what=what, check=check)

    def vector_value(self, value: Any, n: int, path: str, *, what: str = "", check: Check | None = None
                     ) -> tuple[float, ...]:
        """:meth:`vector` for a value found elsewhere (inside a mapping of a calibration file), at ``path``."""
        ok = isinstance(value, list | tuple) and len(value) == n and all(finite_number(x) for x in value)
        if not ok:
            self.fail_at(path, f"must be {what or f'{n} finite numbers'}, got {show(value)}")
        out = tuple(float(x) for x in value)
        if check is not None:
            self.check_plausible(path, check, out)
        return out

    # -- the one mount parser -----------------------------------------------------------------------
    def pose(self, *, rotation_required: bool, translation: Check = plausible.mount_translation) -> Pose:
        """``xyz`` (default zero) and exactly one of ``quat_xyzw``, ``rpy``, ``rotvec`` (identity when none
        is given and ``rotation_required`` is False); ``translation`` checks how far ``xyz`` reaches."""
        given = [k for k in ROTATION_KEYS if k in self]
        if len(given) > 1 or (rotation_required and not given):
            what = f"two rotations ({' and '.join(given)})" if given else "no rotation"
            self.fail(f"{what}: give either rpy or quat_xyzw or rotvec, one only {_ROTATION_HELP}")
        x, y, z = self.vector("xyz", 3, (0.0, 0.0, 0.0), check=translation) or (0.0, 0.0, 0.0)
        if not given:
            return Pose((x, y, z), (0.0, 0.0, 0.0, 1.0))
        key = given[0]
        if key == "quat_xyzw":
            q = self.vector(key, 4) or ()
            norm = math.sqrt(sum(c * c for c in q))
            if abs(norm - 1.0) > 1e-3:
                self.fail(f"quat_xyzw {list(q)} has norm {norm:.6g}, not 1 (order is x, y, z, w)")
            # Renormalise only what is off by more than rounding, so that writing and reading back is exact.
            quat = tuple(c / norm for c in q) if abs(norm - 1.0) > 1e-15 else q
        else:
            values = np.array(self.vector(key, 3, check=lambda v: plausible.angles(v, key)))
            quat = tuple((quat_from_rpy(values) if key == "rpy" else quat_from_rotvec(values)).tolist())
        return Pose((x, y, z), (quat[0], quat[1], quat[2], quat[3]))
