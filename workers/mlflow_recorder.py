"""Provides MlflowRecorder: a trial recorder that logs to one MLflow run."""

from __future__ import annotations

import time
from pathlib import Path

from mlflow.entities import Metric
from mlflow.tracking import MlflowClient
from mlflow.utils.async_logging.run_operations import RunOperations

ARTIFACT_SUFFIXES: tuple[str, ...] = (".csv", ".parquet", ".json", ".png", ".gif", ".pt")
"""The trial files logged at the end; the checkpoint folder and temp files stay local."""


class MlflowRecorder:
    """Logs a trial's per-iteration metrics and final files to an existing MLflow run.

    Each iteration's metrics go out in one asynchronous `log_batch`, so the write overlaps
    the next evaluation; `flush` (called by `log_artifacts`) waits for all of them and
    raises if any failed.

    Args:
        client: a client on the run's tracking URI.
        run_id: the run to log to.
    """

    def __init__(self, client: MlflowClient, run_id: str):
        self._client = client
        self._run_id = run_id
        self._pending: list[RunOperations] = []

    def log_iteration(self, iteration: int, metrics: dict[str, float]) -> None:
        """Queues one iteration's metrics as one `log_batch`, with `step = iteration`."""
        timestamp = int(time.time() * 1000)
        batch = [
            Metric(key=name, value=float(value), timestamp=timestamp, step=int(iteration))
            for name, value in metrics.items()
        ]
        if batch:
            operation = self._client.log_batch(self._run_id, metrics=batch, synchronous=False)
            if operation is not None:
                self._pending.append(operation)

    def flush(self) -> None:
        """Waits until every queued metric batch is written (raises if one failed)."""
        pending, self._pending = self._pending, []
        for operation in pending:
            operation.wait()

    def log_artifacts(self, out_dir: Path) -> None:
        """Flushes the metrics, then logs the trial's result files in `out_dir` at the run's
        artefact root."""
        self.flush()
        for path in sorted(Path(out_dir).iterdir()):
            if path.is_file() and path.suffix in ARTIFACT_SUFFIXES:
                self._client.log_artifact(self._run_id, str(path))
