"""Provides MLflow store resolution and the experiment set-up shared by every writer."""

from __future__ import annotations

import os
from pathlib import Path

DEFAULT_STORE_DIR = Path("runs")
"""Where the embedded store lives, relative to the working directory, unless told."""
DEFAULT_EXPERIMENT = "linkevo"


def default_tracking_uri(store_dir: Path | None = None) -> str:
    """Returns the absolute sqlite URI of the embedded store (`<store_dir>/mlflow.db`)."""
    root = (store_dir or DEFAULT_STORE_DIR).resolve()
    return f"sqlite:///{root / 'mlflow.db'}"


def resolve_tracking_uri(uri: str | None = None) -> str:
    """Returns an absolute tracking URI.

    Order: the explicit `uri`, then `MLFLOW_TRACKING_URI`, then the embedded default.
    Relative sqlite paths are made absolute (MLflow resolves them against each process's
    working directory, which differs between the driver and Ray workers); a bare path is
    taken as a directory for an embedded store.
    """
    uri = uri or os.environ.get("MLFLOW_TRACKING_URI") or default_tracking_uri()
    if uri.startswith("sqlite:///"):
        path = Path(uri.removeprefix("sqlite:///"))
        return f"sqlite:///{path.resolve()}"
    if "://" not in uri:
        return default_tracking_uri(Path(uri))
    return uri


def artifact_root_for(uri: str) -> str | None:
    """Returns the local artifact folder URI for an embedded sqlite store, else None."""
    if uri.startswith("sqlite:///"):
        return (Path(uri.removeprefix("sqlite:///")).parent / "mlartifacts").as_uri()
    return None


def ensure_experiment(uri: str, name: str = DEFAULT_EXPERIMENT) -> str:
    """Creates the store and experiment if needed (driver side, before any fan-out).

    Returns the experiment id. Creating the sqlite schema from one process first avoids
    the migration race that concurrent first writers hit.
    """
    from mlflow.tracking import MlflowClient

    if uri.startswith("sqlite:///"):
        Path(uri.removeprefix("sqlite:///")).parent.mkdir(parents=True, exist_ok=True)
    client = MlflowClient(tracking_uri=uri)
    experiment = client.get_experiment_by_name(name)
    if experiment is not None:
        return experiment.experiment_id
    return client.create_experiment(name, artifact_location=artifact_root_for(uri))
