"""A short fixed-seed run of the log fuzzer (``make fuzz`` runs 10,000 cases): damaged copies of
small real logs through ``info``, ``tf``, ``replay`` and ``attribute`` with no traceback, hang or
exit code other than 0 or 1, and the cut property on them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers.realdata import TF_EXAMPLE_BAG

ROOT = Path(__file__).resolve().parents[3]
SMALL_LOGS = ("tf_example.bag", "tf_example", "nav2_turtlebot.mcap")


def test_short_fixed_seed_fuzz_run(realdata: Path) -> None:
    if not (realdata / TF_EXAMPLE_BAG).is_file():
        pytest.skip("the real logs are not present")
    run = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "fuzz.py"), "--cases", "9", "--seed", "1", "--jobs", "1",
         "--realdata", str(realdata),
         "--timeout", "60", "--logs", ",".join(SMALL_LOGS), "--random-cuts", "3", "--max-boundaries", "6",
         "--json"],
        capture_output=True, text=True, timeout=240, check=False,
    )
    summary = json.loads(run.stdout)
    assert summary["cases"] == 9
    assert summary["failures"] == []
    assert summary["statuses"] == {"ok": 9}
    # Every log was cut: its salvage never lost a complete message, nor gave back a changed one.
    assert {Path(p["log"]).name for p in summary["cut_property"]} == {"tf_example.bag", "nav2_turtlebot.mcap"}
    assert summary["cut_property_problems"] == 0
    assert run.returncode == 0
