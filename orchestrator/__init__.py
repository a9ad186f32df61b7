"""linkevo's orchestrator layer."""
