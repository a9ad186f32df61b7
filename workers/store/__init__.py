"""Where results are kept: the MLflow store (its URI, experiment and run layout), the
recorder that logs a trial, linkage references read back from runs, and atomic files.

This is the one interface through which `hardware/` reads and writes results (field
trials are MLflow runs; telemetry files are written atomically).
"""
