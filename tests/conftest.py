"""Shared test helpers: paths to ../shared/realdata and seeded generators."""

from __future__ import annotations

import os

# One BLAS thread per test process: `make test` runs two xdist workers on two cores, and OpenBLAS's own
# threads (one per core in each worker) spin for the CPU without making a fit any faster. Set before numpy
# is first imported; subprocesses the tests start (the CLI) inherit it.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# The report's figures drawn in each test's own process: renderer processes (two per report command)
# would double the processes on the two cores; tests/sinks/test_plots.py and tests/cli/test_commands.py
# start them where they are what is tested.
os.environ.setdefault("FRAMECHAIN_RENDERERS", "0")

from pathlib import Path

import numpy as np
import pytest
from shared_paths import REALDATA

# Tests reach the real logs through the ``realdata`` fixture, so each skips cleanly without them.


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


@pytest.fixture(scope="session")
def realdata() -> Path:
    """The real logs' folder (../shared/realdata); the test is skipped when it is absent."""
    if not REALDATA.is_dir():
        pytest.skip(f"real logs not found at {REALDATA}")
    return REALDATA
