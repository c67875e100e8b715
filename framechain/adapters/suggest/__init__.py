"""What a log has against what a chain needs: the frame tree, the suggested chain, the marker probe."""
