"""Geometry every room shares: rotations in every parametrisation (quaternions x, y, z, w; rotation
vectors; URDF roll-pitch-yaw; matrices), rigid transforms, the REP-103 conventions, and the camera
model (pinhole with its distortion: pixels to rays and back)."""
