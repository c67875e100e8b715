"""Fixtures of the LeRobot tests: the arm datasets in both formats, robot.yaml, the real data."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

HERE = str(Path(__file__).resolve().parent)
if HERE not in sys.path:
    sys.path.insert(0, HERE)

from lerobot_scene import ArmDataset, write_arm_dataset  # noqa: E402

FORMATS = ("v2.1", "v3.0")


@pytest.fixture(scope="session", params=FORMATS)
def arm_dataset(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> ArmDataset:
    """Three episodes (24, 40, 30 frames) of the arm, no camera delay, a detection feature."""
    version = str(request.param)
    root = tmp_path_factory.mktemp(f"arm_{version}") / "dataset"
    return write_arm_dataset(root, version=version, detection_feature=True,
                             episodes_per_file=2 if version == "v3.0" else None)


@pytest.fixture
def unitree(realdata: Path) -> Path:
    return realdata / "lerobot" / "unitree_g1_v21"


@pytest.fixture
def gr00t(realdata: Path) -> Path:
    return realdata / "lerobot" / "gr00t_pick_n_place_v20"


@pytest.fixture
def so101_urdf(realdata: Path) -> Path:
    return realdata / "urdf" / "so101" / "so101_new_calib.urdf"
