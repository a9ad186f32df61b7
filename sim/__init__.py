"""linkevo's sim layer."""
