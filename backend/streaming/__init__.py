"""What clients receive of a run: stream frames, their fan-out, the series as JSON, the rerun web viewer."""
