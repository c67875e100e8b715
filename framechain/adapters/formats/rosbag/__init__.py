"""ROS 1 bags and ROS 2 bags (sqlite3 or MCAP storage): the reader through rosbags, and the salvage
scanners for damaged bags."""
