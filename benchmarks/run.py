"""Run the benchmarks: every ``benchmarks/bench_*.py`` module's ``main() -> None``.

Usage: ``python benchmarks/run.py [NAME_FILTER]``; with a filter only the modules whose name
contains it run (``python benchmarks/run.py lookup``). Benchmarks print figures; they never
assert on absolute times.
"""

from __future__ import annotations

import importlib.util
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def discover(name_filter: str = "") -> list[Path]:
    """The benchmark modules, sorted by name, whose stem contains ``name_filter``."""
    return [p for p in sorted(HERE.glob("bench_*.py")) if name_filter in p.stem]


def run(path: Path) -> None:
    """Import one benchmark module by its own name (process pools can pickle its functions) and run it."""
    if str(path.parent) not in sys.path:
        sys.path.insert(0, str(path.parent))
    spec = importlib.util.spec_from_file_location(path.stem, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[path.stem] = module
    spec.loader.exec_module(module)
    main = getattr(module, "main", None)
    if not callable(main):
        raise AttributeError(f"{path.name} has no main() -> None")
    main()


def cli(argv: list[str]) -> int:
    if len(argv) > 1 or (argv and argv[0] in {"-h", "--help"}):
        print(__doc__)
        return 0 if argv and argv[0] in {"-h", "--help"} else 2
    name_filter = argv[0] if argv else ""
    paths = discover(name_filter)
    if not paths:
        print(f"no benchmark matches {name_filter!r}", file=sys.stderr)
        return 1
    for path in paths:
        print(f"== {path.stem}", flush=True)
        start = time.perf_counter()
        run(path)
        print(f"   ({path.stem}: {time.perf_counter() - start:.1f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(cli(sys.argv[1:]))
