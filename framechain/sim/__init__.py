"""Scene generator: simulated episodes with known faults."""
