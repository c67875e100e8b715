"""Scene generator: simulated episodes with known faults, written as real logs.

The truth is computed with the generator's own maths (:mod:`framechain.sim.rigid`), never the
replay's, so that scenes can check the product rather than agree with it.
"""

from framechain.sim.logs import write_scene
from framechain.sim.scene import ExpectedFinding, InjectedFault, Scene, SceneError, SceneSpec, generate

__all__ = ["ExpectedFinding", "InjectedFault", "Scene", "SceneError", "SceneSpec", "generate", "write_scene"]
