"""The root exception of framechain.

Every room raises a subclass of :class:`FramechainError`; the CLI turns any of them into one line on stderr and a
non-zero exit. Messages are built from structured fields so that callers can also read the fields.
"""

from __future__ import annotations

__all__ = ["FramechainError", "one_line"]


class FramechainError(Exception):
    """Root of every error framechain raises on purpose (a user mistake or bad input)."""


def one_line(err: BaseException) -> str:
    """An error's message on one line (another library's may span several), or its type's name when it has none."""
    return " ".join(str(err).split()) or type(err).__name__
