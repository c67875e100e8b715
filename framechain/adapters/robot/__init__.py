"""The robot side of a log: URDF forward kinematics, robot.yaml, and what a chain file adds (camera
models from calibration files, mounts and URDF fixed joints as static edges)."""
