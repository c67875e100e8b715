"""Where the shared real logs live, importable by name from any test folder (each folder's own
``conftest`` shadows the top one under ``import conftest``)."""

from __future__ import annotations

from pathlib import Path

PROJECT = Path(__file__).resolve().parents[1]
#: The real robot logs (never copied into the project).
REALDATA = PROJECT.parent / "shared" / "realdata"
