"""The chain as a function of its faults: the vectorised chain under a perturbation, and the fault catalogue's
models (each camera's faults on a rig, wrong frames), with their typed estimates."""
