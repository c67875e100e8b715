"""Errors of the adapters room: one line naming the file, the topic and what is wrong."""

from __future__ import annotations

from pathlib import Path

from framechain.errors import FramechainError


class AdapterError(FramechainError):
    """A log could not be read (or not fully): built from the file, the topic and what is wrong."""

    def __init__(self, path: str | Path, what: str, *, topic: str | None = None) -> None:
        self.path = str(path)
        self.topic = topic
        self.what = what
        where = f"{self.path}: topic {topic}" if topic else self.path
        super().__init__(f"{where}: {what}")


class UnsupportedLogError(AdapterError):
    """Not a log framechain can read: unknown content, a directory that is not a bag."""


class EmptyLogError(AdapterError):
    """The log holds no messages (or none on the topics asked for)."""


class CorruptLogError(AdapterError):
    """The file is damaged beyond what can be salvaged (bad magic, unreadable index)."""


class SchemaError(AdapterError):
    """A message type whose definition is missing, unknown or cannot be decoded."""
