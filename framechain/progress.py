"""How far a long run is: one callable every stage reports to, the CLI renders (a bar on a terminal, plain
lines in a CI log) and the library ignores by default.

A report is the stage's name, and for a stage that counts (messages read, bootstrap resamples, fits) how
many of how many are done and of what: ``progress("reading run.bag", 4096, 270_000, "messages")``.
"""

from __future__ import annotations

from typing import Protocol


class Progress(Protocol):
    """Told each stage by name and, for a counted stage, ``done`` of ``total`` ``unit``."""

    def __call__(self, stage: str, /, done: int | None = None, total: int | None = None, unit: str = "") -> None: ...


def no_progress(stage: str, /, done: int | None = None, total: int | None = None, unit: str = "") -> None:
    """The Progress of a run nobody watches."""


__all__ = ["Progress", "no_progress"]
