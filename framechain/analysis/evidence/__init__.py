"""The evidence a chain is judged against: the replay aligned with the robot's logged points, static targets,
cross-camera sightings, a rig's cameras against each other, labels whose size is wrong."""
