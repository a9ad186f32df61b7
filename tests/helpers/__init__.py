"""Helpers the tests and benchmarks share: tiny grids and MLflow queries (`grid`), a
synthetic grid store for the report (`report`), hexapod configs for the emulator
(`hexapod`). Imported as `tests.helpers.<module>`, with the repository root on the path
(pytest's `pythonpath`), so they work under every pytest import mode."""
