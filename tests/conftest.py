"""Shared test helpers: paths to ../shared/realdata and seeded generators."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

PROJECT = Path(__file__).resolve().parents[1]
#: The real robot logs (never copied into the project). Tests reach them through the ``realdata``
#: fixture only, so each skips cleanly on a machine without them.
REALDATA = PROJECT.parent / "shared" / "realdata"


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


@pytest.fixture(scope="session")
def realdata() -> Path:
    """The real logs' folder (../shared/realdata); the test is skipped when it is absent."""
    if not REALDATA.is_dir():
        pytest.skip(f"real logs not found at {REALDATA}")
    return REALDATA
