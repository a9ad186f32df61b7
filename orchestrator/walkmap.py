"""Provides `walk_map`: every chosen cell of a repertoire walked on the simulated robot,
on each floor, fanned out over Ray (`linkevo walkmap`) in two steps: the cells' legs built
in batches of cells, then each distinct leg walked once, in batches of legs
(`sim.walk_map`).

The result is the trial's `walkmap.parquet` (a row per cell and floor: `sim.walk_map.COLUMNS`
and the cell's bins) and `walkmap.png` (distance per cell, a panel per floor), logged to
the trial's run. Rows are logged as they come, every `CHECKPOINT_S`, so `--resume` after an
interruption walks only what is missing (and what failed).
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from linkevo.orchestrator.explore import TrialRun
from linkevo.sim import decode, simulate
from linkevo.sim.errors import LinkevoError
from linkevo.sim.physical import physical_checks
from linkevo.sim.walk_map import COLUMNS, CellBatch
from linkevo.sim.walk_map import walk_rows as _walk_rows
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.artifacts import write_parquet_atomic

BATCH_CELLS = 8
"""Cells per build task (1-2 s of work on one core)."""
BATCH_LEGS = 4
"""Distinct legs per walk task: a task walks them on every floor (about 2 s of work on one
core), small enough that the tasks of one repertoire spread evenly over the workers."""
CHECKPOINT_S = 30.0
"""How often the rows walked so far are logged to the trial's run."""
SELECTIONS = ("buildable", "all", "best:K")


class WalkMapError(LinkevoError, ValueError):
    """A walk map that cannot be made as asked; the message says what would do."""


@dataclass(frozen=True)
class Selection:
    """Which cells to walk: "buildable" (those that pass the 2-D physical checks, walked as
    their LEGO build where one turns), "all" (every cell, as evolved where no LEGO build
    turns) or the `best` lowest-loss buildable ones."""

    kind: str
    best: int = 0

    @classmethod
    def parse(cls, text: str) -> Selection:
        if text in ("buildable", "all"):
            return cls(text)
        head, _, count = text.partition(":")
        if head == "best" and count.isdigit() and int(count) >= 1:
            return cls("best", int(count))
        raise WalkMapError(f"--cells {text!r}: allowed {', '.join(SELECTIONS)} (K >= 1)")

    def choose(self, table: pd.DataFrame, mode: str) -> pd.DataFrame:
        """Returns the repertoire rows (ascending loss) to walk."""
        table = table.sort_values(["loss", "cell"], kind="stable").reset_index(drop=True)
        if self.kind == "all":
            return table
        genomes = np.stack(table["genome"].to_numpy()).astype(np.float64)
        batch = decode(genomes, mode)
        keep = physical_checks(batch, simulate(batch)).buildable
        chosen = table[keep]
        return chosen.head(self.best) if self.kind == "best" else chosen


def plan(
    chosen: pd.DataFrame,
    mode: str,
    floors: tuple[str, ...],
    done: pd.DataFrame | None,
    *,
    as_evolved: bool,
    seconds: float,
) -> list[CellBatch]:
    """Returns the batches still to walk: the chosen cells on every floor, less the (cell,
    floor) pairs `done` already holds with a status other than "failed"."""
    finished: set[tuple[int, str]] = set()
    if done is not None and not done.empty:
        ok = done[done["status"] != "failed"]
        finished = set(zip(ok["cell"].astype(int), ok["floor"], strict=True))
    batches: dict[tuple[str, ...], list[int]] = {}
    for i, cell in enumerate(chosen["cell"].astype(int)):
        todo = tuple(f for f in floors if (cell, f) not in finished)
        if todo:
            batches.setdefault(todo, []).append(i)
    out = []
    for todo, rows in batches.items():
        for start in range(0, len(rows), BATCH_CELLS):
            part = chosen.iloc[rows[start : start + BATCH_CELLS]]
            out.append(
                CellBatch(
                    cells=part["cell"].to_numpy(dtype=np.int64),
                    genomes=np.stack(part["genome"].to_numpy()).astype(np.float64),
                    mode=mode,
                    floors=todo,
                    as_evolved=as_evolved,
                    seconds=seconds,
                )
            )
    return out


Runner = Callable[[Callable[[Any], Any], list], Iterable[Any]]
"""Runs a function over items and yields each result as it ends: `run_in_process`, or
`run_on_ray` bound to a cluster."""


def walk_rows(
    run: Runner, batches: list[CellBatch], seconds: float
) -> Iterator[tuple[int, list[dict]]]:
    """`sim.walk_map.walk_rows` in tasks of `BATCH_LEGS` distinct legs: yields, as each
    task ends, how many cells it built and the rows it settled."""
    return _walk_rows(run, batches, seconds, BATCH_LEGS)


def run_in_process(work: Callable[[Any], Any], items: list) -> Iterator[Any]:
    """Yields `work(item)` for each item, here, one after another."""
    for item in items:
        yield work(item)


def _on_one_core(work: Callable[[Any], Any], item: Any) -> Any:
    """`work(item)` in a task that holds one CPU: numba's and BLAS's thread pools kept to
    one thread, so tasks side by side do not compete for cores."""
    import numba
    from threadpoolctl import threadpool_limits

    numba.set_num_threads(1)
    with threadpool_limits(1):
        return work(item)


def run_on_ray(work: Callable[[Any], Any], items: list, in_flight: int) -> Iterator[Any]:
    """Yields `work(item)` for each item as its Ray task ends (one CPU per task, at most
    `in_flight` tasks submitted at a time so an interruption leaves little running)."""
    import ray

    task = ray.remote(num_cpus=1, max_retries=2)(_on_one_core)
    pending = list(items)
    running: list = []
    try:
        while pending or running:
            while pending and len(running) < in_flight:
                running.append(task.remote(work, pending.pop(0)))
            ready, running = ray.wait(running, num_returns=1)
            yield ray.get(ready[0])
    finally:
        for ref in running:
            ray.cancel(ref, force=True)


def refuse_overwrite(client, trial: TrialRun, resume: bool) -> None:
    """Raises WalkMapError when the trial's run has a walk map and `resume` is off, so
    nothing is overwritten unasked."""
    if resume:
        return
    names = {a.path for a in client.list_artifacts(trial.run_id)}
    if layout.WALK_MAP in names:
        raise WalkMapError(
            f"run {trial.run_id} ({trial.trial_key}) already has a walk map; add --resume "
            "to walk only the cells it lacks"
        )


def walk_map(
    client,
    trial: TrialRun,
    run: Runner,
    *,
    floors: tuple[str, ...],
    selection: Selection,
    resume: bool,
    seconds: float,
    tick: Callable[[str, int, int], None] | None = None,
) -> pd.DataFrame:
    """Walks one repertoire trial's chosen cells and logs its walk map; returns it.

    Args:
        run: runs the build and walk tasks (`run_in_process`, or `run_on_ray` bound to a
            cluster).
        resume: complete the map the run already has (without it, a run that has one is
            refused, so nothing is overwritten unasked).
        tick: called as tasks end with ("building legs", cells built, cells), then with
            ("walking", pairs done, pairs); a (cell, floor) pair is done when its row is
            known (a cell that is not walked, as it is built).

    Raises:
        WalkMapError: the run has a walk map and `resume` is off.
    """
    from linkevo.workers.store.linkages import repertoire
    from linkevo.workers.store.linkages import walk_map as stored_map

    refuse_overwrite(client, trial, resume)
    with tempfile.TemporaryDirectory(prefix="linkevo-walkmap-") as tmp:
        table = repertoire(client, trial.run_id, Path(tmp) / "in")
        done = stored_map(client, trial.run_id, Path(tmp) / "done")
        chosen = selection.choose(table, trial.mode)
        batches = plan(
            chosen, trial.mode, floors, done, as_evolved=selection.kind == "all", seconds=seconds
        )
        kept = (
            []
            if done is None
            else [done[done["status"] != "failed"].reindex(columns=list(COLUMNS))]
        )
        rows: list[dict] = []
        total = sum(len(b.cells) * len(b.floors) for b in batches)
        cells, built = sum(len(b.cells) for b in batches), 0
        last = time.monotonic()
        try:
            for n_built, new_rows in walk_rows(run, batches, seconds):
                rows += new_rows
                built += n_built
                if tick is not None and built < cells:
                    tick("building legs", built, cells)
                elif tick is not None:
                    tick("walking", len(rows), total)
                if time.monotonic() - last > CHECKPOINT_S:
                    _log(client, trial, table, kept, rows, Path(tmp), picture=False)
                    last = time.monotonic()
        finally:
            result = _log(client, trial, table, kept, rows, Path(tmp), picture=True)
    return result


def _log(client, trial, table, kept, rows, tmp: Path, *, picture: bool) -> pd.DataFrame:
    """Logs the walk map so far (rows kept from before and walked now) to the trial's run;
    returns it."""
    frame = pd.concat([*kept, pd.DataFrame(rows, columns=list(COLUMNS))], ignore_index=True)
    frame = frame.drop_duplicates(["cell", "floor"], keep="last").sort_values(["floor", "cell"])
    bins = [c for c in sorted(table.columns) if c.startswith("bin_")]
    frame = frame.merge(table[["cell", *bins]], on="cell", how="left").reset_index(drop=True)
    path = tmp / layout.WALK_MAP
    write_parquet_atomic(path, {c: frame[c].to_numpy() for c in frame.columns})
    client.log_artifact(trial.run_id, str(path))
    if picture and not frame.empty:
        from linkevo.workers.plots.walk_map import draw_walk_map

        png = draw_walk_map(frame, trial, tmp / layout.WALK_MAP_PNG)
        client.log_artifact(trial.run_id, str(png))
    walked = frame[frame["status"] == "walked"]
    for floor, part in walked.groupby("floor"):
        distances = part.loc[~part["breaks"], "mean_distance_cm"].to_numpy(dtype=float)
        best = float(np.nanmax(distances)) if np.isfinite(distances).any() else math.nan
        if math.isfinite(best):
            client.log_metric(trial.run_id, f"walk_best_cm_{floor}", best)
        client.log_metric(trial.run_id, f"walk_cells_{floor}", float(len(part)))
    return frame
