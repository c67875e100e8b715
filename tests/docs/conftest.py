"""The inputs the documentation's blocks run beside (``in=`` of a block's check), each laid into the test's
folder: the real logs from ../shared/realdata (linked, never copied), the demo's output, and a generated
SO-101 dataset with LeRobot calibration files ("so101"; "so101_urdf": the URDF alone). A missing input
skips the blocks that need it, with the reason."""

from __future__ import annotations

import contextlib
import io
import json
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tests.helpers.realdata import SO101_URDF

#: Inputs that are folders of ../shared/realdata, their files linked in ("fleet": the stairs bag without the
#: tutorial's chain.yaml, which only files of the input "stairs" get).
_REAL = {"stairs": "tagslam_stairs", "fleet": "tagslam_stairs", "quad_rig": "tagslam_quad_rig", "evo": "evo"}
_SO101_JOINTS = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")


def _link_all(source: Path, folder: Path) -> None:
    for entry in source.iterdir():
        if not (folder / entry.name).exists():  # two inputs' LICENSE files: the first one's
            (folder / entry.name).symlink_to(entry)


def _demo(folder: Path) -> None:
    """``framechain demo --out demo`` in ``folder``."""
    from framechain.cli.main import main

    before = Path.cwd()
    os.chdir(folder)
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["demo", "--out", "demo", "-q", "--no-rrd"]) == 0
    finally:
        os.chdir(before)


def _so101_dataset(root: Path) -> None:
    """A one-episode SO-101 recording in degrees (the docs' robot.yaml reads it) with a wrist video key, and
    ``detections.parquet`` of one still object seen from the wrist camera."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from framechain.adapters.lerobot.writer import EpisodeData, FeatureSpec, write_lerobot_dataset

    n = 60
    t = np.arange(n) / 30
    state = np.column_stack([20 * np.sin(t * w) for w in (1.0, 0.7, 0.9, 1.3, 0.5)] + [np.full(n, 30.0)])
    features = {
        "observation.state": FeatureSpec("float32", (6,), [f"{j}.pos" for j in _SO101_JOINTS]),
        "observation.images.wrist": FeatureSpec("video", (480, 640, 3), ["height", "width", "channels"],
                                                {"video.fps": 30, "video.codec": "av1", "video.is_depth_map": False}),
    }
    write_lerobot_dataset(root / "so101_dataset", [EpisodeData({"observation.state": state.astype(np.float32)})],
                          features=features, fps=30, version="v3.0")
    frames = np.arange(0, n, 3)
    pq.write_table(pa.table({"episode_index": np.zeros(frames.size, np.int64), "frame_index": frames,
                             "camera": ["wrist_cam"] * frames.size, "u": 320.0 + 5 * np.sin(frames / 7),
                             "v": 240.0 + 5 * np.cos(frames / 7), "depth_m": np.full(frames.size, 0.3)}),
                   root / "detections.parquet")


def _lerobot_calibrations(folder: Path) -> None:
    """LeRobot calibration JSONs of two SO-101 followers (the docs' two-arm example names them)."""
    motors = {j: {"id": i + 1, "drive_mode": 0, "homing_offset": 0, "range_min": 1000, "range_max": 3000}
              for i, j in enumerate(_SO101_JOINTS)}
    for arm in ("left", "right"):
        (folder / f"{arm}_follower.json").write_text(json.dumps(motors))


@pytest.fixture(scope="session")
def doc_inputs(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory,
               ) -> Callable[[str, Path], None]:
    """Lays the named inputs (``a+b``: both) into a folder (skipping the test when they are not on this machine)."""
    made: dict[str, Path] = {}

    def realdata() -> Path:
        root: Path = request.getfixturevalue("realdata")  # skips the test without ../shared/realdata
        return root

    def lay(names: str, folder: Path) -> None:
        for name in names.split("+"):
            lay_one(name, folder)

    def lay_one(name: str, folder: Path) -> None:
        if name == "empty":
            return
        if name in _REAL:
            source = realdata() / _REAL[name]
            if not source.is_dir():
                pytest.skip(f"{source} not present")
            _link_all(source, folder)
        elif name == "demo":
            if "demo" not in made:
                made["demo"] = tmp_path_factory.mktemp("demo")
                _demo(made["demo"])
            _link_all(made["demo"], folder)
        elif name in ("so101", "so101_urdf"):
            urdf = realdata() / SO101_URDF
            if not urdf.is_file():
                pytest.skip(f"{urdf} not present")
            (folder / urdf.name).symlink_to(urdf)
            if name == "so101":
                _so101_dataset(folder)
                _lerobot_calibrations(folder)
        else:
            raise AssertionError(f"no input named {name!r} for the docs' blocks")

    return lay
