"""Fixtures of the adapter tests: one seeded scene written once per session in every container."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from framechain.adapters import CONTAINERS, write_log
from framechain.timeline import Timeline
from tests.helpers.adapter_scene import CHAIN, make_scene

SUFFIX = {"mcap-ros2": ".mcap", "mcap-ros1": ".mcap", "rosbag1": ".bag", "rosbag2-sqlite": "", "rosbag2-mcap": ""}


@pytest.fixture(scope="session")
def scene() -> Timeline:
    return make_scene(np.random.default_rng(20261122))


@pytest.fixture(scope="session")
def written(scene: Timeline, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The scene in each of the five containers."""
    out = tmp_path_factory.mktemp("containers")
    return {c: write_log(scene, out / f"scene_{c}{SUFFIX[c]}", container=c, chain=CHAIN) for c in CONTAINERS}
