"""Message kinds into timeline rows: transforms, camera info, detections (vision_msgs, AprilTag,
ArUco, fiducials), markers found in images, depth and camera images, side tables."""
