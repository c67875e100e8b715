"""Sinks: Rerun streams and report rendering."""
