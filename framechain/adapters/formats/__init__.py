"""Log containers: MCAP (ROS 2, ROS 1, Foxglove encodings), ROS 1 and ROS 2 bags; their readers,
salvage scanners for damaged files, the writers, and CDR decoding. Every reader hands its raw
messages to the one decode loop (``decode_loop``), which fills the collector."""
