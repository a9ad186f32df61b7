"""Helpers for the grid tests: tiny grid configs and MLflow run queries."""

from __future__ import annotations

import collections
from pathlib import Path

from mlflow.tracking import MlflowClient

from linkevo.orchestrator import config
from linkevo.orchestrator.grid import Grid

TINY = {
    "trials": 2,
    "approaches": ["EA", "MAP-LIS"],
    "fitnesses": ["Fp", "Fsl"],
    "evaluations": 400,
    "batch_size": 200,
    "n_angles": 24,
    "checkpoint_every": 1,
    "evaluators_per_trial": 1,
    "cpus_per_evaluator": 1.0,
}
"""A 2 approaches x 2 fitness x 2 trials grid of 2 iterations of 200 evaluations."""


def tiny_config_file(tmp_path: Path, **changes: object) -> Path:
    """Writes the tiny grid (with `changes`) as TOML and returns its path."""
    cfg = config.from_dict({**TINY, **changes})
    path = tmp_path / "tiny.toml"
    path.write_text(config.to_toml(cfg))
    return path


def tiny_grid(tmp_path: Path, **changes: object) -> Grid:
    """Returns the tiny grid with its store in `tmp_path/store` (unless changed)."""
    changes.setdefault("tracking_uri", f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}")
    return Grid.from_config(config.load(tiny_config_file(tmp_path, **changes)))


def runs_by_key(uri: str, grid_id: str) -> dict[str, list[tuple[str, str]]]:
    """Returns trial key -> [(run_id, status), ...] for every trial run of the grid."""
    client = MlflowClient(uri)
    experiment = client.get_experiment_by_name("linkevo")
    out: dict[str, list[tuple[str, str]]] = collections.defaultdict(list)
    if experiment is None:
        return out
    runs = client.search_runs(
        [experiment.experiment_id],
        f"tags.grid_id = '{grid_id}' and tags.`linkevo.kind` = 'trial'",
        max_results=1000,
    )
    for run in runs:
        out[run.data.tags["trial_key"]].append((run.info.run_id, run.info.status))
    return out


def running_on(uri: str, grid_id: str, node_id: str) -> str | None:
    """Returns the key of a trial running on `node_id` that has logged an iteration."""
    client = MlflowClient(uri)
    experiment = client.get_experiment_by_name("linkevo")
    if experiment is None:
        return None
    runs = client.search_runs(
        [experiment.experiment_id],
        f"tags.grid_id = '{grid_id}' and attributes.status = 'RUNNING' "
        f"and tags.ray_node = '{node_id}'",
    )
    for run in runs:
        if "evaluations" in run.data.metrics:
            return run.data.tags["trial_key"]
    return None
