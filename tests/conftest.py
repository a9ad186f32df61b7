"""Fixtures shared by every test package, and the one worker that runs every test module
that starts Ray."""

from __future__ import annotations

import numpy as np
import pytest

from linkevo.workers.evaluators import Evaluator, Stateless

RAY_MODULES = frozenset(
    {
        "tests/orchestrator/test_cluster.py",
        "tests/orchestrator/test_driver.py",
        "tests/orchestrator/test_grid_faults.py",
        "tests/orchestrator/test_local_cluster.py",
        "tests/orchestrator/test_report_grid.py",
        "tests/orchestrator/test_walkmap.py",
        "tests/workers/test_ray_evaluator.py",
    }
)
"""The modules whose tests start Ray (in process, or through `linkevo` subprocesses)."""


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Puts every test that starts Ray on one pytest-xdist worker (`--dist loadgroup`): one
    Ray instance at a time, as on a developer's machine; every other test is spread over
    the cores meanwhile."""
    root = config.rootpath
    for item in items:
        if item.path.relative_to(root).as_posix() in RAY_MODULES:
            item.add_marker(pytest.mark.xdist_group("ray"))


class CrashingEvaluator(Stateless):
    """Evaluates normally, then raises on call number `fail_at` (a crash mid-trial)."""

    def __init__(self, inner: Evaluator, fail_at: int) -> None:
        self.inner = inner
        self.calls = 0
        self.fail_at = fail_at

    def submit(self, genomes: np.ndarray, bar=None):
        self.calls += 1
        if self.calls == self.fail_at:
            raise RuntimeError("evaluator crashed")
        return self.inner.submit(genomes, bar)

    def __call__(self, genomes: np.ndarray):
        return self.submit(genomes)()


@pytest.fixture
def crashing_evaluator() -> type[CrashingEvaluator]:
    """Returns the CrashingEvaluator class: `crashing_evaluator(inner, fail_at=k)`."""
    return CrashingEvaluator


@pytest.fixture
def mlflow_server(tmp_path):
    """A real `mlflow server` on loopback; yields its URI. Its sqlite store and proxied
    artefacts lie in tmp_path/mlflow-server (artefacts in its artefacts/ folder)."""
    from tests.helpers.mlflow_server import mlflow_server as serve

    with serve(tmp_path / "mlflow-server") as uri:
        yield uri


@pytest.fixture(scope="module")
def ray_local():
    """One small local Ray instance for the whole test module."""
    import ray

    # "local": a new instance even while a `ray start` cluster of another test is up
    ray.init(
        address="local", num_cpus=2, object_store_memory=200 * 1024**2, include_dashboard=False
    )
    yield ray
    ray.shutdown()
