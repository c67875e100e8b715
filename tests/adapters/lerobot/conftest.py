"""Fixtures of the LeRobot dataset tests: the arm datasets in both formats."""

from __future__ import annotations

import pytest

from tests.helpers.lerobot_scene import ArmDataset, write_arm_dataset

FORMATS = ("v2.1", "v3.0")


@pytest.fixture(scope="session", params=FORMATS)
def arm_dataset(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> ArmDataset:
    """Three episodes (24, 40, 30 frames) of the arm, no camera delay, a detection feature."""
    version = str(request.param)
    root = tmp_path_factory.mktemp(f"arm_{version}") / "dataset"
    return write_arm_dataset(root, version=version, detection_feature=True,
                             episodes_per_file=2 if version == "v3.0" else None)

