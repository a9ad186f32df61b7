"""linkevo's hardware layer."""
