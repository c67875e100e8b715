"""A short fixed-seed run of the configuration fuzzer (``make fuzz`` runs 1,500 cases): mutated copies
of the tutorial's tagslam_stairs chain, of the Kalibr cameras.yaml beside it (and a ROS camera_info made
from it), and of a robot.yaml for a real LeRobot dataset, through ``info`` and ``attribute``: exit 0
(the mutation happened to be valid) or 1 with one line on stderr, never a traceback."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers.realdata import STAIRS_BAG, UNITREE

ROOT = Path(__file__).resolve().parents[2]


def test_mutated_configuration_files_give_one_line_never_a_traceback(realdata: Path) -> None:
    if not (realdata / STAIRS_BAG).is_file() or not (
            realdata / UNITREE).is_dir():
        pytest.skip("the tagslam_stairs bag or the unitree dataset is not present")
    run = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "fuzz_config.py"), "--cases", "210", "--seed", "1", "--mix",
         "chain=5,calibration=1,robot=1", "--attribute-every", "15", "--jobs", "2", "--timeout", "60",
         "--realdata", str(realdata), "--json"],
        capture_output=True, text=True, timeout=300, check=False,
    )
    summary = json.loads(run.stdout)
    assert summary["cases"] == 210
    # 150 mutated chains (10 through attribute), 30 calibration files, 30 robot.yaml.
    assert summary["targets"] == {"chain info": 140, "chain attribute": 10, "calibration info": 30, "robot info": 30}
    assert summary["failures"] == []
    assert summary["statuses"] == {"ok": 210}
    # Both kinds of mutation were met: the ones that happen to stay valid and the ones refused in one line.
    assert set(summary["exit_codes"]) == {"0", "1"}
    assert run.returncode == 0
