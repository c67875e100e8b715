"""The analysis room: fault models, attribution, evidence files."""
