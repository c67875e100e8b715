"""A short fixed-seed run of the dataset fuzzer (``make fuzz`` runs 300 cases): damaged copies of generated
v3.0 / v2.1 datasets with video and of the real ones through ``info``, ``info --episode``, ``tf`` and
``attribute``, with no traceback, hang, exit code other than 0 or 1, or exit 1 that is not one line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers.realdata import SO101_URDF

ROOT = Path(__file__).resolve().parents[3]


def test_short_fixed_seed_dataset_fuzz_run(realdata: Path) -> None:
    if not (realdata / SO101_URDF).is_file():
        pytest.skip("the SO-101 URDF is not present")
    run = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "fuzz_datasets.py"), "--cases", "32", "--seed", "1", "--json"],
        capture_output=True, text=True, timeout=600, check=False,
    )
    summary = json.loads(run.stdout)
    assert summary["cases"] == 32
    assert summary["failures"] == []
    assert summary["statuses"] == {"ok": 32}
    # Every command ran, and damage was said in one line as often as it stopped a case.
    assert {t.split()[1] for t in summary["targets"]} == {"info", "tf", "attribute"}
    assert any(t.endswith("info --episode") for t in summary["targets"])
    assert summary["exit_codes"].get("1", 0) >= 4
    assert run.returncode == 0
