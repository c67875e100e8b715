"""Conventions every room shares (REP-103)."""

from __future__ import annotations

#: camera_link (x forward, y left, z up) -> its optical frame (x right, y down, z forward), REP-103:
#: what ``static_transform_publisher 0 0 0 -1.5708 0 -1.5708 camera_link camera_optical_frame`` publishes.
OPTICAL_FROM_LINK_QUAT_XYZW: tuple[float, float, float, float] = (-0.5, 0.5, -0.5, 0.5)
