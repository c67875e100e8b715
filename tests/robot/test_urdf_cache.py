"""The cache of parsed URDFs: a second read of the same text gives the same joints without yourdfpy, a changed text
is parsed again, and a cache that cannot be read or written costs nothing but the parse."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from framechain.robot import urdf as urdf_module
from framechain.robot.kinematics import RobotModel
from framechain.robot.urdf import CACHE_ENV, JointType, UrdfJoints, read_urdf, read_urdf_text

ARM = """<?xml version="1.0"?>
<robot name="two_link">
  <link name="base"/><link name="upper"/><link name="slide"/><link name="finger"/><link name="tool"/>
  <link name="floater"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0.1 -0.2 0.3" rpy="0.3 -0.4 1.2"/><axis xyz="0 0 2"/>
    <limit lower="-1.5" upper="2.25" effort="1" velocity="1"/>
  </joint>
  <joint name="rail" type="prismatic">
    <parent link="upper"/><child link="slide"/>
    <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.04" effort="1" velocity="1"/>
  </joint>
  <joint name="finger_joint" type="prismatic">
    <parent link="slide"/><child link="finger"/><axis xyz="0 1 0"/>
    <limit lower="-0.04" upper="0" effort="1" velocity="1"/>
    <mimic joint="rail" multiplier="-1" offset="0.001"/>
  </joint>
  <joint name="tool_mount" type="fixed">
    <parent link="finger"/><child link="tool"/><origin xyz="0 0 0.07" rpy="3.14159 0 0"/>
  </joint>
  <joint name="loose" type="floating"><parent link="base"/><child link="floater"/></joint>
</robot>
"""


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    folder = tmp_path / "cache"
    monkeypatch.setenv(CACHE_ENV, str(folder))
    return folder


def _no_parse(*_args: object) -> UrdfJoints:
    raise AssertionError("parsed again: the cache was not used")


def _same(a: UrdfJoints, b: UrdfJoints) -> None:
    assert (a.name, a.unsupported) == (b.name, b.unsupported)
    assert [(j.name, j.type, j.parent, j.child, j.lower, j.upper, j.mimic) for j in a.joints] == \
        [(j.name, j.type, j.parent, j.child, j.lower, j.upper, j.mimic) for j in b.joints]
    for x, y in zip(a.joints, b.joints, strict=True):
        assert np.array_equal(x.origin, y.origin)  # exactly: JSON keeps reprs
        assert np.array_equal(x.axis, y.axis)


def test_second_read_comes_from_the_cache_with_the_same_joints(tmp_path: Path, cache: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "arm.urdf"
    path.write_text(ARM)
    first = read_urdf(path)
    assert len(list((cache / "urdf").glob("*.json"))) == 1
    monkeypatch.setattr(urdf_module, "_parse_urdf", _no_parse)
    second = read_urdf(path)
    _same(first, second)
    assert second.source == str(path)
    # Against the URDF's own numbers, worked independently (scipy's extrinsic xyz = URDF rpy).
    shoulder = second.joints[0]
    assert shoulder.type is JointType.REVOLUTE
    assert (shoulder.lower, shoulder.upper) == (-1.5, 2.25)
    np.testing.assert_allclose(shoulder.origin[:3, :3], Rotation.from_euler("xyz", [0.3, -0.4, 1.2]).as_matrix(),
                               atol=1e-12)
    np.testing.assert_allclose(shoulder.origin[:3, 3], [0.1, -0.2, 0.3])
    np.testing.assert_allclose(shoulder.axis, [0, 0, 1])  # normalised
    finger = next(j for j in second.joints if j.name == "finger_joint")
    assert finger.mimic is not None
    assert (finger.mimic.joint, finger.mimic.multiplier, finger.mimic.offset) == ("rail", -1.0, 0.001)
    assert second.unsupported == [("loose", "floating")]


def test_same_text_from_a_log_shares_the_entry_and_a_changed_text_is_parsed_again(
        tmp_path: Path, cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "arm.urdf"
    path.write_text(ARM)
    from_file = read_urdf(path)
    calls: list[str] = []
    parse = urdf_module._parse_urdf

    def counted(file: object, source: str) -> UrdfJoints:
        calls.append(source)
        return parse(file, source)  # type: ignore[arg-type]

    monkeypatch.setattr(urdf_module, "_parse_urdf", counted)
    from_log = read_urdf_text(ARM, "/robot_description")
    assert calls == []
    assert from_log.source == "/robot_description"
    _same(from_file, from_log)
    changed = read_urdf_text(ARM.replace('upper="2.25"', 'upper="2.5"'), "/robot_description")
    assert calls == ["/robot_description"]
    assert changed.joints[0].upper == 2.5
    assert len(list((cache / "urdf").glob("*.json"))) == 2


def test_an_unreadable_entry_is_parsed_again_and_replaced(tmp_path: Path, cache: Path) -> None:
    path = tmp_path / "arm.urdf"
    path.write_text(ARM)
    first = read_urdf(path)
    (entry,) = (cache / "urdf").glob("*.json")
    entry.write_text('{"name": "two_link", "joints": [{"name": ')  # a write cut short
    _same(first, read_urdf(path))
    _same(first, read_urdf(path))
    assert entry.read_text().endswith("}")


def test_no_cache_when_disabled_or_unwritable(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "arm.urdf"
    path.write_text(ARM)
    monkeypatch.setenv(CACHE_ENV, "")
    assert urdf_module.cache_dir() is None
    disabled = read_urdf(path)
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("a file where the cache folder would be")
    monkeypatch.setenv(CACHE_ENV, str(blocker))
    _same(disabled, read_urdf(path))  # parsed; nothing kept, nothing raised
    assert blocker.read_text().startswith("a file")


def test_bad_urdf_is_not_cached(tmp_path: Path, cache: Path) -> None:
    path = tmp_path / "bad.urdf"
    path.write_text(ARM.replace('<axis xyz="0 0 2"/>', '<axis xyz="0 0 0"/>'))
    with pytest.raises(Exception, match="zero axis"):
        read_urdf(path)
    assert not list(cache.rglob("*.json"))


def test_a_later_command_does_not_import_yourdfpy(tmp_path: Path, cache: Path) -> None:
    """What the cache is for: a process that reads a URDF parsed before never imports yourdfpy (and trimesh)."""
    path = tmp_path / "arm.urdf"
    path.write_text(ARM.replace('<joint name="loose" type="floating"><parent link="base"/><child link="floater"/>'
                                "</joint>", ""))
    script = ("import sys; from pathlib import Path; from framechain.robot.kinematics import RobotModel; "
              f"m = RobotModel.from_urdf(Path({str(path)!r})); print(len(m.joints), 'yourdfpy' in sys.modules)")
    runs = [subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.split()
            for _ in range(2)]
    assert runs == [["4", "True"], ["4", "False"]]
    assert len(RobotModel.from_urdf(path).joints) == 4
