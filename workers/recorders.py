"""Provides the trial Recorder protocol, the no-op and progress-bar recorders, and the
metrics.csv log every trial writes."""

from __future__ import annotations

import csv
import errno
import io
import os
import sys
from pathlib import Path
from typing import Protocol

from tqdm import tqdm

from linkevo.workers.checkpoint import checkpointed_rows
from linkevo.workers.store.artifacts import disk_full, write_text_atomic


class Recorder(Protocol):
    """Where a trial reports besides its own files (MLflow, a progress bar, nothing)."""

    def log_iteration(self, iteration: int, metrics: dict[str, float]) -> None:
        """Takes one iteration's metrics (also called for replayed rows on resume)."""
        ...

    def log_artifacts(self, out_dir: Path) -> None:
        """Takes the trial's final files (called once, at the end)."""
        ...


class NullRecorder:
    """Records nothing."""

    def log_iteration(self, iteration: int, metrics: dict[str, float]) -> None:
        """Ignores the metrics."""

    def log_artifacts(self, out_dir: Path) -> None:
        """Ignores the files."""


class ProgressRecorder:
    """Shows a tqdm progress bar on stderr: evaluations (or walks), best loss, coverage.

    Args:
        total: the budget: evaluations, or a walking trial's walks.
        unit: the bar's unit ("eval" or "walk").
        counter: the metric the bar follows ("evaluations" or "walks").
        disable: hide the bar.
    """

    def __init__(
        self, total: int, unit: str = "eval", counter: str = "evaluations", disable: bool = False
    ) -> None:
        self._counter = counter
        self._bar = tqdm(total=total, unit=unit, unit_scale=True, file=sys.stderr, disable=disable)

    def log_iteration(self, iteration: int, metrics: dict[str, float]) -> None:
        """Moves the bar to the evaluations (walks) done and shows best loss and coverage
        (a row of end-of-trial measures alone, such as `path_diversity`, leaves it as it
        is)."""
        if self._counter not in metrics:
            return
        self._bar.n = int(metrics[self._counter])
        self._bar.set_postfix(
            best=f"{metrics['best_loss']:.3f}", coverage=f"{metrics['coverage']:.3f}", refresh=False
        )
        self._bar.refresh()

    def log_artifacts(self, out_dir: Path) -> None:
        """Closes the bar."""
        self._bar.close()

    def close(self) -> None:
        """Closes the bar (idempotent)."""
        self._bar.close()


class MetricsCsv:
    """The per-iteration metrics file of a trial: one row per iteration, flushed each time.

    Floats are written with `repr`, so reading a row back gives the identical value.

    Args:
        path: the CSV file.
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)

    def reset(self) -> None:
        """Removes the file, for a fresh trial."""
        self.path.unlink(missing_ok=True)

    def append(self, metrics: dict[str, float]) -> None:
        """Appends one row (writing the header first if the file is new)."""
        new = not self.path.exists() or self.path.stat().st_size == 0
        try:
            with open(self.path, "a", newline="") as f:
                writer = csv.writer(f)
                if new:
                    writer.writerow(list(metrics))
                writer.writerow([repr(float(v)) for v in metrics.values()])
                f.flush()
                os.fsync(f.fileno())
        except OSError as exc:
            if exc.errno in (errno.ENOSPC, errno.EDQUOT):
                raise disk_full(self.path, None, self.path.stat().st_size) from exc
            raise

    def read(self) -> list[dict[str, float]]:
        """Returns every row as floats (empty when there is no file)."""
        if not self.path.exists():
            return []
        with open(self.path, newline="") as f:
            return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]

    def truncate(self, rows: int) -> list[dict[str, float]]:
        """Keeps only the first `rows` rows (atomically rewritten); returns them.

        Raises:
            CheckpointError: when the file holds fewer whole rows than asked for.
        """
        kept = checkpointed_rows(self.path, rows)
        if not kept:
            self.reset()
            return kept
        buffer = io.StringIO(newline="")
        writer = csv.writer(buffer)
        writer.writerow(list(kept[0]))
        writer.writerows([repr(v) for v in row.values()] for row in kept)
        write_text_atomic(self.path, buffer.getvalue())
        return kept
