"""Provides the grid's live progress view on stderr."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from linkevo.orchestrator.fan_out import TrialContext
    from linkevo.orchestrator.grid import Grid
    from linkevo.workers.trial_task import TrialOutcome

PROGRESS_POLL_SECONDS = 5.0
"""How often the progress view reads the running trials' evaluation counts from MLflow."""


class Progress:
    """The live view on stderr: trials done / running / failed and evaluations per second."""

    def __init__(self, ctx: TrialContext, grid: Grid, done: int, enabled: bool, stream: TextIO):
        from tqdm import tqdm

        self._ctx = ctx
        self._stream = stream
        self._grid_id = grid.grid_id
        self._start_ms = int(time.time() * 1000)
        self._start = time.monotonic()
        self._last_poll = 0.0
        self._rate = 0.0
        self._ended_evaluations = 0.0
        self.failed = 0
        self._bar = tqdm(
            total=len(grid.cells),
            initial=done,
            unit="trial",
            desc=f"grid {grid.grid_id}",
            file=stream,
            disable=not enabled,
            dynamic_ncols=True,
        )

    def _poll_rate(self) -> None:
        # Only the runs in flight are read: reading the whole grid every poll costs time
        # in proportion to the grid on the tracking server (docs/scale.md). A silent
        # server is not asked (the rate stays as it was).
        if self._ctx.watch.down_since is not None:
            return
        try:
            runs = self._ctx.store.trial_runs(self._grid_id, status="RUNNING")
        except Exception:  # the server went silent since the watch last asked
            return
        evaluations = self._ended_evaluations + sum(
            r.data.metrics.get("evaluations", 0.0)
            for r in runs
            if r.info.start_time >= self._start_ms
        )
        self._rate = evaluations / max(time.monotonic() - self._start, 1e-9)

    def ended(self, outcome: TrialOutcome) -> None:
        """Counts the evaluations of a trial that ended in this launch."""
        self._ended_evaluations += outcome.evaluations or 0

    def update(self, running: int, finished: int, failed: int) -> None:
        """Refreshes the view; reads MLflow at most every PROGRESS_POLL_SECONDS."""
        self.failed += failed
        now = time.monotonic()
        if not self._bar.disable and now - self._last_poll >= PROGRESS_POLL_SECONDS:
            self._last_poll = now
            self._poll_rate()
        self._bar.set_postfix(
            running=running, failed=self.failed, evals_per_s=f"{self._rate:,.0f}", refresh=False
        )
        self._bar.update(finished + failed)

    def say(self, line: str) -> None:
        """Prints a line above the bar (or alone, without one)."""
        self._bar.write(line, file=self._stream)

    def close(self) -> None:
        """Closes the bar."""
        self._bar.close()
