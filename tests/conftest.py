"""Fixtures every test folder may use: a seeded generator, and the real logs' folder with named paths in it."""

from __future__ import annotations

import atexit
import os
import shutil
import tempfile

# One BLAS thread per test process: `make test` runs two xdist workers on two cores, and OpenBLAS's own
# threads (one per core in each worker) spin for the CPU without making a fit any faster. Set before numpy
# is first imported; subprocesses the tests start (the CLI) inherit it.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# The report's figures drawn in each test's own process: renderer processes (two per report command)
# would double the processes on the two cores; tests/sinks/test_plots.py and tests/cli/test_commands.py
# start them where they are what is tested.
os.environ.setdefault("FRAMECHAIN_RENDERERS", "0")
# framechain's cache (parsed URDFs) in a folder of this test process's own, never the user's: the CLI subprocesses
# the tests start use it too, and tests/robot/test_urdf_cache.py sets its own.
os.environ["FRAMECHAIN_CACHE_DIR"] = tempfile.mkdtemp(prefix="framechain-test-cache-")

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tests.helpers.realdata import GR00T, REALDATA, SO101_URDF, UNITREE
from tests.helpers.rerun_server import GrpcServer, serving_grpc

atexit.register(shutil.rmtree, os.environ["FRAMECHAIN_CACHE_DIR"], ignore_errors=True)

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


@pytest.fixture(scope="session")
def so101_urdf(realdata: Path) -> Path:
    """The published SO-101 URDF (the arm the generated LeRobot episodes move)."""
    return realdata / SO101_URDF


@pytest.fixture(scope="session")
def unitree(realdata: Path) -> Path:
    return realdata / UNITREE


@pytest.fixture(scope="session")
def gr00t(realdata: Path) -> Path:
    return realdata / GR00T


@pytest.fixture
def grpc_server(tmp_path: Path) -> Iterator[GrpcServer]:
    """A Rerun gRPC server saving what it receives (the Rerun sink's and the replay command's tests stream to it)."""
    with serving_grpc(tmp_path) as server:
        yield server
