"""Provides MlflowRecorder: a trial recorder that logs to one MLflow run."""

from __future__ import annotations

import math
import time
from pathlib import Path

from mlflow.entities import Metric
from mlflow.tracking import MlflowClient

from linkevo.workers.store.outage import OUTAGE_LIMIT_S, ServerLost, answers, patiently

ARTIFACT_SUFFIXES: tuple[str, ...] = (".csv", ".parquet", ".json", ".png", ".gif", ".pt")
"""The trial files logged at the end; the checkpoint folder and (hidden) temporary files
are never logged."""
SEND_EVERY_S = 2.0
"""Seconds between metric sends: the MLflow UI and the grid's progress lag by at most this."""
MAX_BATCH = 1000
"""Metrics per `log_batch` call (MLflow's limit)."""


class MlflowRecorder:
    """Logs a trial's per-iteration metrics and final files to an existing MLflow run.

    The first iteration's metrics are sent at once (the run shows progress from the
    start); later ones are gathered and sent every `send_every_s` seconds. One `log_batch`
    costs about 8 ms of Python (SQLAlchemy) on a sqlite store whatever its size up to a
    few hundred metrics, so one per iteration would slow every iteration (docs/grid.md,
    "Metrics go to MLflow every 2 s"). Sends are synchronous: MLflow's asynchronous
    writer thread polls its queue and takes about 1 s to stop when the run ends, longer
    than a small trial.
    `flush` (called by `log_artifacts`, and by the trial task when a trial fails) sends
    what is gathered.

    Args:
        client: a client on the run's tracking URI.
        run_id: the run to log to.
        send_every_s: seconds between sends (0 sends every iteration).
        outage_s: how long a silent tracking server is waited for (`workers.store.outage`):
            meanwhile the metrics stay gathered and the trial goes on.
    """

    def __init__(
        self,
        client: MlflowClient,
        run_id: str,
        send_every_s: float = SEND_EVERY_S,
        outage_s: float = OUTAGE_LIMIT_S,
    ):
        self._client = client
        self._run_id = run_id
        self._send_every_s = send_every_s
        self._outage_s = outage_s
        self._gathered: list[Metric] = []
        self._sent_at = -float("inf")  # the first iteration goes out at once
        self._silent_since: float | None = None

    def log_iteration(self, iteration: int, metrics: dict[str, float]) -> None:
        """Gathers one iteration's metrics with `step = iteration`; sends when it is time.

        A metric that does not apply in this iteration (NaN: MAP-AU's `recon_loss` between
        trainings, say) is not logged, so the MLflow UI never shows it as NaN; `metrics.csv`
        keeps every column.
        """
        timestamp = int(time.time() * 1000)
        self._gathered += [
            Metric(key=name, value=float(value), timestamp=timestamp, step=int(iteration))
            for name, value in metrics.items()
            if math.isfinite(value)
        ]
        if time.monotonic() - self._sent_at >= self._send_every_s:
            self._send()

    def _send(self) -> None:
        """Sends what is gathered. While the tracking server does not answer, the metrics
        stay gathered (the trial goes on) and are sent when it answers again; past
        `outage_s` of silence this raises `ServerLost`."""
        self._sent_at = time.monotonic()
        uri = self._client.tracking_uri
        while self._gathered:
            part = self._gathered[:MAX_BATCH]
            try:
                self._client.log_batch(self._run_id, metrics=part)
            except Exception:
                if answers(uri):
                    raise
                self._silent_since = self._silent_since or time.time()
                if time.time() - self._silent_since > self._outage_s:
                    raise ServerLost(uri, self._silent_since, self._outage_s) from None
                return
            self._silent_since = None
            del self._gathered[: len(part)]

    def flush(self) -> None:
        """Sends the gathered metrics, waiting (up to `outage_s`) for a silent server."""
        patiently(self._flush_now, self._client.tracking_uri, self._outage_s)

    def _flush_now(self) -> None:
        self._send()
        if self._gathered:
            raise ConnectionError("the tracking server does not answer")

    def log_artifacts(self, out_dir: Path) -> None:
        """Flushes the metrics, then logs the trial's result files in `out_dir` at the run's
        artefact root (waiting, up to `outage_s`, for a silent server)."""
        self.flush()
        for path in sorted(Path(out_dir).iterdir()):
            hidden = path.name.startswith(".")  # temporary files of a writer, never results
            if path.is_file() and path.suffix in ARTIFACT_SUFFIXES and not hidden:
                patiently(
                    lambda p=path: self._client.log_artifact(self._run_id, str(p)),
                    self._client.tracking_uri,
                    self._outage_s,
                )
