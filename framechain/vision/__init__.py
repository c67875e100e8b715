"""Image algorithms: a square marker's pose from its corners (PnP), markers found in images, feature tracks and a
camera's rotation between frames (two-view geometry), on one camera model."""
