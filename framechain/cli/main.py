"""The ``framechain`` command: parse, call a library function, render; errors become one line.

Each command lives in its own module of this package with ``register(subparsers)`` and a
``run(args) -> int``; heavy imports (rerun, matplotlib, readers) happen inside ``run``.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import importlib
import os
import sys
from collections.abc import Sequence
from types import ModuleType
from typing import Any, NoReturn

from framechain import __version__

#: Command modules, in the order ``--help`` lists them.
COMMANDS = ("info", "tf", "replay", "attribute", "batch", "report", "export", "demo", "lab")

EXIT_OK = 0
EXIT_INPUT_ERROR = 1  # the log, chain or options could not be used: one line on stderr says why
EXIT_USAGE = 2  # the command line itself is wrong (argparse)
EXIT_INTERRUPTED = 130
#: The BLAS thread pools (OpenBLAS as NumPy and SciPy ship it, MKL) a command runs with one thread.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

EPILOG = """exit codes:
  0    success (for attribute: the log was analysed, whatever was found)
  1    bad input: the log, the chain configuration or an option could not be used (one line on stderr)
  2    usage error: unknown command or option
  130  interrupted
"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="framechain",
        description="Log-replay frame-chain debugger: recompute every hop of the pixel-to-world chain "
        "from a recorded log and name the hop, the fault, its size and the fix.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"framechain {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        module = _command_module(name)
        if module is not None:
            module.register(sub)
    _add_exit_codes(sub)
    return parser


class _KeepLaidOutText(argparse.HelpFormatter):
    """Wrap one-paragraph descriptions; keep text laid out in lines (the exit-code table) as it is."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if "\n" in text.strip("\n"):
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)


def _add_exit_codes(sub: Any) -> None:
    """Every command's --help ends with the exit codes (a command may give its own, more precise)."""
    for command in sub.choices.values():
        if command.epilog is None:
            command.epilog = EPILOG
            command.formatter_class = _KeepLaidOutText
        for action in command._actions:  # nested commands (`lab tilt`)
            if isinstance(action, argparse._SubParsersAction):
                _add_exit_codes(action)


def _command_module(name: str) -> ModuleType | None:
    try:
        return importlib.import_module(f"framechain.cli.{name}_cmd")
    except ModuleNotFoundError as err:
        if err.name == f"framechain.cli.{name}_cmd":
            return None  # command not built yet
        raise


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "run", None):
        parser.print_help()
        return EXIT_USAGE
    # framechain's matrices are tall and thin (observations x a few parameters): a BLAS thread pool
    # only spins on them, costing more CPU than the attribution itself. Set before NumPy loads; a value
    # the user set wins.
    for variable in BLAS_THREAD_VARIABLES:
        os.environ.setdefault(variable, "1")
    from framechain.cli.common import resolve_datasets
    from framechain.errors import FramechainError  # after parsing, so that --help loads no tables

    try:
        resolve_datasets(args)
        code = int(args.run(args))
        sys.stdout.flush()  # a reader gone before the last buffered line (`| head -1`) is met here, not at exit
        return code
    except FramechainError as err:
        print(f"framechain {args.command}: error: {err}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except BrokenPipeError:
        # The reader went away (`framechain tf ... | head`): not an error of ours; stop quietly.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except OSError as err:  # a path the user gave cannot be read or written
        where = f": {err.filename}" if err.filename else ""
        print(f"framechain {args.command}: error: {err.strerror or err}{where}", file=sys.stderr)
        return EXIT_INPUT_ERROR
    except KeyboardInterrupt:
        print("framechain: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def entry() -> NoReturn:
    """The ``framechain`` console script: :func:`main`, then the process's end without the interpreter's teardown.

    When :func:`main` returns, the command's outputs are written and closed and its workers joined; what libraries
    keep for the process's end still runs (``atexit``: multiprocessing's, temporary folders' finalizers), the output
    streams are flushed, and the process exits. The teardown it skips frees every module's objects one by one: 0.13
    s of a LeRobot episode's 2 s (a generated two-camera 224x224 episode), and on a 10-minute log it would end in a
    full collection that walks every object to free nothing the exit does not (0.12 s)."""
    code = main()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):  # a reader gone (`| head`), or a stream closed
            stream.flush()
    os._exit(code)


if __name__ == "__main__":
    entry()
