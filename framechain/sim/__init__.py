"""Scene generator: simulated episodes with known faults, written as real logs."""

from framechain.sim.logs import write_scene
from framechain.sim.scene import InjectedFault, Scene, SceneError, SceneSpec, generate

__all__ = ["InjectedFault", "Scene", "SceneError", "SceneSpec", "generate", "write_scene"]
