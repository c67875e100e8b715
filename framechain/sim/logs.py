"""Writing generated scenes as real robot logs (the adapters' writers, every container)."""

from __future__ import annotations

from pathlib import Path

from framechain.adapters import write_log
from framechain.sim.scene import Scene

SUFFIX = {"mcap-ros2": ".mcap", "mcap-ros1": ".mcap", "rosbag1": ".bag", "rosbag2-sqlite": "", "rosbag2-mcap": ""}


def write_scene(scene: Scene, path: str | Path, *, container: str = "mcap-ros2", depth_encoding: str = "16UC1") -> Path:
    """Write the scene's timeline on the chain's topics; returns the log path (file or bag directory)."""
    return write_log(scene.timeline, path, container=container, chain=scene.chain, depth_encoding=depth_encoding)
