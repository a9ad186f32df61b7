"""linkevo's workers layer."""
