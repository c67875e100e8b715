"""Tag sizes written in files beside a log: TagSLAM's ``default_tag_size`` and each tag's own ``size``, a Kalibr
aprilgrid target's ``tagSize``, a chain file's ``evidence.tag_size_m``; as the chain's ``evidence.tag_size_m``.

A tag declared at the wrong size puts every depth from its corners off by the same factor, so a static tag seen
from different distances spreads along the rays as if it moved: the per-tag sizes a file gives are worth as much
as its default.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, TypeGuard

from framechain.suggest.facts import BesideHint, from_file, is_chain_file

#: Nesting a tag size is looked for down to (TagSLAM's tags sit under bodies: house: tags: - id, size).
MAX_DEPTH = 8


def tag_sizes(beside: list[tuple[str, Any]]) -> float | dict[str, float] | None:
    """The tag sizes of the first file beside the log that gives any (a tag map or target before a chain file): one
    size, or ``{default: size, id: size}``."""
    for _name, raw in _targets_first(beside):
        sizes = _file_sizes(raw)
        if sizes is not None:
            return sizes[0]
    return None


def tag_size_hint(beside: list[tuple[str, Any]]) -> BesideHint | None:
    """``evidence.tag_size_m: {default: 0.16, 100: 0.1}`` from the first file beside the log that gives sizes, with
    the file and key it came from."""
    for name, raw in _targets_first(beside):
        sizes = _file_sizes(raw)
        if sizes is not None:
            value, key = sizes
            return BesideHint(f"evidence.tag_size_m: {size_text(value)}", from_file(name, key))
    return None


def same_sizes(a: float | dict[str, float] | None, b: float | dict[str, float] | None) -> bool:
    """Whether two declarations give every tag the same size (one number is the default of all)."""
    def as_dict(value: float | dict[str, float] | None) -> dict[str, float]:
        if value is None:
            return {}
        return {"default": float(value)} if isinstance(value, float | int) else {str(k): float(v) for k, v in
                                                                                 value.items()}

    left, right = as_dict(a), as_dict(b)
    tags = set(left) | set(right)
    return all(left.get(t, left.get("default")) == right.get(t, right.get("default")) for t in tags)


def size_text(value: float | dict[str, float]) -> str:
    """``0.16``, or ``{default: 0.16, 100: 0.1}`` (flow YAML, as the chain writes it)."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {v:g}" for k, v in value.items()) + "}"
    return f"{value:g}"


def _targets_first(beside: list[tuple[str, Any]]) -> list[tuple[str, Any]]:
    """The files beside the log, those that describe the tags (TagSLAM, Kalibr targets) before chain files."""
    return sorted(beside, key=lambda item: is_chain_file(item[0]))


def _file_sizes(raw: Any) -> tuple[float | dict[str, float], str] | None:
    """One file's tag sizes and the key that gave them (None: it gives none)."""
    default: list[tuple[float, str]] = []
    sizes: dict[str, float] = {}

    def walk(value: Any, depth: int = 0) -> None:
        if depth > MAX_DEPTH:
            return
        if isinstance(value, Mapping):
            _sizes_here(value, default, sizes)
            for v in value.values():
                walk(v, depth + 1)
        elif isinstance(value, list):
            for v in value:
                walk(v, depth + 1)

    walk(raw)
    if not default and not sizes:
        return None
    if not sizes:
        return default[0]
    key = default[0][1] if default else "size"
    if default:  # a tag of the default size needs no entry of its own
        sizes = {tag: size for tag, size in sizes.items() if size != default[0][0]}
        if not sizes:
            return default[0]
    merged = {**({"default": default[0][0]} if default else {}), **sizes}
    return merged, (f"{key} and each tag's size" if default else "each tag's size")


def _sizes_here(value: Mapping[Any, Any], default: list[tuple[float, str]], sizes: dict[str, float]) -> None:
    """The sizes one mapping gives: a default (TagSLAM's ``default_tag_size``, Kalibr's aprilgrid ``tagSize``, a
    chain's ``tag_size_m``), and a tag's own (TagSLAM's ``{id, size}``)."""
    for key in ("default_tag_size", "tag_size", "tag_size_m"):
        size = value.get(key)
        if isinstance(size, Mapping):  # a chain's {default: 0.16, 100: 0.1}
            for tag, own in size.items():
                if str(tag) == "default" and _size(own):
                    default.append((float(own), key))
                elif _size(own):
                    sizes.setdefault(str(tag), float(own))
        elif _size(size):
            default.append((float(size), key))
    if str(value.get("target_type", "")).strip("'\"") == "aprilgrid" and _size(value.get("tagSize")):
        default.append((float(value["tagSize"]), "tagSize of the aprilgrid target"))
    own = value.get("size")
    if "id" in value and _size(own):
        sizes.setdefault(str(value["id"]), float(own))


def _size(value: Any) -> TypeGuard[float]:
    return isinstance(value, int | float) and not isinstance(value, bool) and 0 < value < 10
