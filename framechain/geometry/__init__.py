"""Geometry every room shares: rotations in every parametrisation (quaternions x, y, z, w; rotation
vectors; URDF roll-pitch-yaw; matrices), rigid transforms, and the REP-103 conventions."""
