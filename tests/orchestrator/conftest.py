"""Shared fixtures for the orchestrator tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def ray_local():
    """One small local Ray instance for the whole test module."""
    import ray

    ray.init(num_cpus=2, object_store_memory=200 * 1024**2, include_dashboard=False)
    yield ray
    ray.shutdown()
