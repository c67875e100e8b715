"""A command imports what it uses: on a robot log, attribute loads neither the viewer, nor OpenCV, nor
pandas, nor the LeRobot reader's compute kernels; without a report, no matplotlib either."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from framechain.catalogue import Fault
from framechain.sim.logs import write_scene
from framechain.sim.scene import InjectedFault, SceneSpec, generate

NEVER = ("rerun", "cv2", "pandas", "pyarrow.compute", "torch", "lerobot")

PROGRAM = """
import json, sys
from framechain.cli.main import main
code = main(sys.argv[1:])
print(json.dumps({"code": code, "modules": sorted(sys.modules)}))
"""


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    out = tmp_path_factory.mktemp("imports")
    scene = generate(SceneSpec(seed=3, duration_s=2.0, width=160, height=120, focal_px=150.0,
                               faults=(InjectedFault(Fault.LATENCY, "robot", {"offset_s": -0.03}),)))
    chain = out / "given.yaml"
    chain.write_text(scene.chain.to_yaml())
    return write_scene(scene, out / "episode.mcap"), chain


def _modules(log: tuple[Path, Path], out: Path, formats: str) -> set[str]:
    path, chain = log
    done = subprocess.run([sys.executable, "-c", PROGRAM, "attribute", str(path), "--chain", str(chain),
                           "--out", str(out), "--format", formats, "--bootstrap", "0", "-q"],
                          capture_output=True, text=True, check=True,
                          env={**os.environ, "FRAMECHAIN_RENDERERS": "0"})
    printed = json.loads(done.stdout.strip().splitlines()[-1])
    assert printed["code"] == 0
    return set(printed["modules"])


@pytest.mark.parametrize("formats", ["json", "json,md,html"])
def test_attribute_on_a_robot_log_imports_only_what_it_uses(log: tuple[Path, Path], tmp_path: Path,
                                                            formats: str) -> None:
    modules = _modules(log, tmp_path / "out", formats)
    assert "framechain.analysis.verdict.attribute" in modules  # the command did run
    assert not [m for m in NEVER if m in modules]
    assert ("matplotlib" in modules) == (formats != "json")  # drawn here: FRAMECHAIN_RENDERERS=0
