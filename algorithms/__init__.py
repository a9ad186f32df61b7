"""linkevo's algorithms layer."""
