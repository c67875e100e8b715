"""``info`` with markers: 0 markers found is a missing piece, and only a dictionary that found
markers is suggested (the UbiquityRobotics ArUco bag: 5x5 markers; the RealSense bag: none).
Skipped when the real logs (``../shared/realdata``) are absent."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from framechain.adapters.api import open_log
from framechain.cli.main import main
from framechain.suggest.chain import suggest
from framechain.suggest.marker_probe import probe_markers
from tests.helpers.realdata import ARUCO_IMAGES_BAG, REALSENSE_BAG

IMAGE = "/raspicam_node/image/compressed"


def _chain(tmp_path: Path, dictionary: str) -> Path:
    chain = tmp_path / "aruco.yaml"
    chain.write_text(yaml.safe_dump({
        "frames": {"camera": "raspicam", "body": "base_link", "world": "map"},
        "topics": {"image": IMAGE, "camera_info": "/raspicam_node/camera_info"},
        "mounts": [{"parent": "base_link", "child": "raspicam", "xyz": [0.1, 0, 0.3],
                    "quat_xyzw": [-0.5, 0.5, -0.5, 0.5]},
                   {"parent": "map", "child": "base_link", "xyz": [0, 0, 0], "rpy": [0, 0, 0]}],
        "evidence": {"markers": {"dictionary": dictionary, "size_m": 0.14}}}))
    return chain


@pytest.fixture(autouse=True)
def aruco(realdata: Path) -> Path:
    bag = realdata / ARUCO_IMAGES_BAG
    if not bag.is_file():
        pytest.skip(f"{bag} not present")
    return bag


def test_zero_markers_is_not_ready_and_names_the_dictionary_that_finds_them(
    aruco: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["info", str(aruco), "--chain", str(_chain(tmp_path, "DICT_4X4_50")), "--json", "-q"]) == 0
    info = json.loads(capsys.readouterr().out)
    detections = next(n for n in info["needs"] if n["piece"] == "detections")
    assert info["ready"] is False
    assert detections["status"] == "missing"
    assert detections["detail"].startswith(f"0 markers found in 1 image of {IMAGE} with DICT_4X4_50")
    # The image holds markers 100, 103, 106, 107, 110, 111, 112 of DICT_5X5_1000 (test_markers.py).
    assert "7 markers of DICT_5X5_1000" in detections["detail"]
    assert detections["key"] == "evidence.markers: {dictionary: DICT_5X5_1000, size_m: 0.14}"
    assert main(["info", str(aruco), "--chain", str(_chain(tmp_path, "DICT_5X5_1000")), "--json", "-q"]) == 0
    assert json.loads(capsys.readouterr().out)["ready"] is True


def test_probe_counts_markers_per_dictionary(aruco: Path) -> None:
    probe = probe_markers(aruco, IMAGE)
    assert probe is not None
    assert probe.images == 1
    assert probe.found["DICT_5X5_1000"] == 7
    assert probe.best == "DICT_5X5_1000"
    assert sum(probe.found.values()) == 7  # no other family reads these markers


def test_suggestion_names_only_a_dictionary_that_found_markers(realdata: Path, aruco: Path) -> None:
    text = suggest(open_log(aruco)).to_yaml()
    assert "dictionary: DICT_5X5_1000" in text
    assert "7 markers of DICT_5X5_1000 in the first 1 image" in text
    # The evidence the FILL IN comments ask for is not also written as false.
    assert "static_target: false" not in text
    assert "evidence.static_target: true" in text
    rs = realdata / REALSENSE_BAG
    if rs.is_file():
        text = suggest(open_log(rs)).to_yaml()
        assert "evidence.markers" not in text
        assert "no markers of DICT_4X4_50" in text


def test_bad_dictionary_error_starts_with_the_chain_file(aruco: Path, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    chain = _chain(tmp_path, "DICT_NOPE")
    assert main(["info", str(aruco), "--chain", str(chain)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert f"error: {chain}: evidence.markers.dictionary 'DICT_NOPE' is not an OpenCV dictionary" in err
