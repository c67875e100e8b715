"""The root exception of framechain.

Every room raises a subclass of :class:`FramechainError`; the CLI turns any of them into one line on stderr and a
non-zero exit. Messages are built from structured fields so that callers can also read the fields.
"""

from __future__ import annotations

__all__ = ["FramechainError", "one_line"]


class FramechainError(Exception):
    """Root of every error framechain raises on purpose (a user mistake or bad input)."""

    def __reduce__(self) -> tuple[object, ...]:
        # Pickled as its class, arguments and fields, rebuilt without calling ``__init__``: a subclass whose
        # ``__init__`` takes its fields (a path, a topic) and passes only its message up would not rebuild from its
        # arguments. A measurement in another process (:func:`framechain.vision.threads.map_forked`) raises it here.
        return _rebuilt, (type(self), self.args, self.__dict__)


def _rebuilt(kind: type[FramechainError], args: tuple[object, ...], fields: dict[str, object]) -> FramechainError:
    err = kind.__new__(kind)
    err.args = args
    err.__dict__.update(fields)
    return err


def one_line(err: BaseException) -> str:
    """An error's message on one line (another library's may span several), or its type's name when it has none."""
    return " ".join(str(err).split()) or type(err).__name__
