"""The float64 geometric kernel: pure functions over numpy arrays."""
