"""LeRobot datasets (v2.0, v2.1, v3.0) read and written with pyarrow alone, and one episode as a Timeline."""
