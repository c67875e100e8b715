"""Tag sizes from the files beside a log: TagSLAM's default and each tag's own size, a Kalibr aprilgrid target's
tagSize, a chain file's sizes after the files that describe the tags; the expected sizes read from the files here
with yaml."""

from __future__ import annotations

from pathlib import Path

import yaml

from framechain.suggest.facts import beside_yaml
from framechain.suggest.tag_sizes import same_sizes, tag_size_hint, tag_sizes
from tests.helpers.realdata import STAIRS

KALIBR_APRILGRID = """target_type: 'aprilgrid' #gridtype
tagCols: 6               #number of apriltags
tagRows: 6               #number of apriltags
tagSize: 0.088           #size of apriltag, edge to edge [m]
tagSpacing: 0.3          #ratio of space between tags to tagSize
"""
KALIBR_CHECKERBOARD = """target_type: 'checkerboard' #gridtype
targetCols: 6               #number of internal chessboard corners
targetRows: 7               #number of internal chessboard corners
rowSpacingMeters: 0.06      #size of one chessboard square [m]
colSpacingMeters: 0.06      #size of one chessboard square [m]
"""


def test_a_kalibr_aprilgrid_target_gives_its_tag_size(tmp_path: Path) -> None:
    (tmp_path / "log.bag").write_bytes(b"")
    (tmp_path / "april_6x6.yaml").write_text(KALIBR_APRILGRID)
    beside = beside_yaml(tmp_path / "log.bag")
    assert tag_sizes(beside) == 0.088
    hint = tag_size_hint(beside)
    assert hint is not None
    assert hint.as_key() == ("evidence.tag_size_m: 0.088  (tagSize of the aprilgrid target in april_6x6.yaml beside "
                             "the log)")


def test_a_checkerboard_has_no_tags(tmp_path: Path) -> None:
    (tmp_path / "log.bag").write_bytes(b"")
    (tmp_path / "checkerboard.yaml").write_text(KALIBR_CHECKERBOARD)
    assert tag_sizes(beside_yaml(tmp_path / "log.bag")) is None


def test_tagslam_s_per_tag_sizes_come_before_a_chain_file_s(tmp_path: Path, realdata: Path) -> None:
    source = realdata / STAIRS / "tagslam.yaml"
    (tmp_path / "log.bag").write_bytes(b"")
    (tmp_path / "tagslam.yaml").write_text(source.read_text())
    (tmp_path / "chain.yaml").write_text("evidence: {tag_size_m: 0.15}\n")  # sorts first, describes no tag
    house = yaml.safe_load(source.read_text())["bodies"][0]["house"]
    default = float(house["default_tag_size"])
    own = {str(t["id"]): float(t["size"]) for t in house["tags"] if float(t["size"]) != default}
    sizes = tag_sizes(beside_yaml(tmp_path / "log.bag"))
    assert sizes == {"default": default, **own}
    assert set(own) == {str(i) for i in range(100, 109)}
    assert not same_sizes(0.16, sizes)
    assert same_sizes({"default": 0.16, **own}, sizes)
