"""The robot: its URDF's forward kinematics (batched), robot.yaml bound to the URDF's joints, and the arms framechain
knows without a robot.yaml (bundled URDFs)."""
