"""Adapters: robot logs (MCAP, ROS 1 bag, ROS 2 bag, LeRobot) into the Timeline."""
