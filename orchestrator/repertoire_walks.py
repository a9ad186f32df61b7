"""Provides `walk_map`: every chosen cell of a repertoire walked on the simulated robot,
on each floor, fanned out over Ray (`linkevo walkmap`) in two steps: the cells' legs built
in batches of cells, then each distinct leg walked once, in batches of legs
(`sim.robot.walk_map`).

The result is the trial's `walkmap.parquet` (a row per cell and floor: `sim.robot.walk_rows.COLUMNS`
and the cell's bins) and `walkmap.png` (distance per cell, a panel per floor), logged to
the trial's run. Rows are logged as they come, every `CHECKPOINT_S`, so `--resume` after an
interruption walks only what is missing (and what failed).
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from linkevo.sim import decode, simulate
from linkevo.sim.errors import LinkevoError
from linkevo.sim.linkage.physical import physical_checks
from linkevo.sim.robot.hexapod import Robot, in_floor_order
from linkevo.sim.robot.walk_map import CellBatch
from linkevo.sim.robot.walk_map import walk_rows as _walk_rows
from linkevo.sim.robot.walk_rows import (
    COLUMNS,
    SLIDING_SHARE,
    Status,
    beyond_bound_share,
    credited_cm,
    slide_share,
    walk_map_frame,
)
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.artifacts import write_parquet_atomic
from linkevo.workers.store.runs import RunStore, TrialRun
from linkevo.workers.store.tables import bin_columns

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
        ok = done[done["status"] != Status.FAILED]
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
    run: Runner, batches: list[CellBatch], seconds: float, robot: Robot | None = None
) -> Iterator[tuple[int, list[dict]]]:
    """`sim.robot.walk_map.walk_rows` in tasks of `BATCH_LEGS` distinct legs: yields, as each
    task ends, how many cells it built and the rows it settled."""
    return _walk_rows(run, batches, seconds, BATCH_LEGS, robot)


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
    `in_flight` tasks submitted at a time so an interruption leaves little running).

    Tasks in flight when the caller stops are not cancelled: a `ray.cancel` that meets a
    task's reply on its way back aborts the driver inside Ray. The command disconnects
    from Ray instead, which ends them (`orchestrator.fan_out` does the same for a grid).
    """
    import ray

    task = ray.remote(num_cpus=1, max_retries=2)(_on_one_core)
    pending = list(items)
    running: list = []
    while pending or running:
        while pending and len(running) < in_flight:
            running.append(task.remote(work, pending.pop(0)))
        ready, running = ray.wait(running, num_returns=1)
        yield ray.get(ready[0])


def check_before_walking(
    store: RunStore,
    trial: TrialRun,
    resume: bool,
    restart: bool,
    robot: Robot | None = None,
    *,
    leased: bool = False,
) -> None:
    """Refuses a walk map that cannot be made as asked, before anything is walked: another process
    is making it (unless this one holds its lease, `leased`), the run has one and neither `resume`
    nor `restart` is on (so nothing is overwritten unasked), resuming would walk another robot than
    the map's (`robot`, against the run's `WALK_MAP_ROBOT` tag), or what it would read is
    missing or damaged (the repertoire; resuming, the walk map).

    Raises:
        Busy: another process holds the run's walk-map lease.
        WalkMapError: the run has a walk map and neither `resume` nor `restart` is on.
        NotFound, ArtefactError: the repertoire or the walk map to resume is missing or
            damaged.
    """
    from linkevo.orchestrator.lease import Lease, Subject

    if not leased:
        Lease.refuse_if_held(store, Subject.walk_map(trial.run_id, trial.trial_key))
    names = store.artefact_names(trial.run_id)
    if layout.WALK_MAP in names and not (resume or restart):
        raise WalkMapError(
            f"run {trial.run_id} ({trial.trial_key}) already has a walk map; add --resume "
            "to walk only the cells it lacks, or --restart to walk the map anew"
        )
    if resume and layout.WALK_MAP in names:
        had = walked_robot(store.tags(trial.run_id))
        wanted = (robot or Robot()).changed()
        if had != wanted:
            raise WalkMapError(
                f"run {trial.run_id} ({trial.trial_key}): its walk map walked the robot "
                f"{json.dumps(had, sort_keys=True)}, this one is "
                f"{json.dumps(wanted, sort_keys=True)} (what differs from the study's robot); "
                "resume with the map's robot config, or --restart to walk the map anew"
            )
    with tempfile.TemporaryDirectory(prefix="linkevo-walkmap-") as tmp:
        store.repertoire(trial.run_id, Path(tmp) / "in")
        if resume:
            store.walk_map(trial.run_id, Path(tmp) / "done")


def robot_tag(robot: Robot) -> str:
    """Returns the `WALK_MAP_ROBOT` tag of a robot: what differs from the study's robot, as
    JSON (`Robot.changed`; "{}" for the study's robot)."""
    return json.dumps(robot.changed(), sort_keys=True)


def walked_robot(tags: dict[str, str]) -> dict:
    """Returns what the robot of a run's walk map changed from the study's (`Robot.changed`):
    its `WALK_MAP_ROBOT` tag, or a map tagged with its physics alone by an older linkevo
    (`WALK_MAP_PHYSICS`); {} for the study's robot."""
    if layout.WALK_MAP_ROBOT in tags:
        return json.loads(tags[layout.WALK_MAP_ROBOT])
    physics = json.loads(tags.get(layout.WALK_MAP_PHYSICS, "{}"))
    return {"physics": physics} if physics else {}


@dataclass(frozen=True)
class WalkMapResult:
    """A walk map as logged: its rows (`sim.robot.walk_rows.COLUMNS` and the cells' bins), and
    whether this call walked anything (False: the map was complete already)."""

    frame: pd.DataFrame
    walked: bool


def walk_map(
    store: RunStore,
    trial: TrialRun,
    run: Runner,
    *,
    floors: tuple[str, ...],
    selection: Selection,
    resume: bool = False,
    restart: bool = False,
    seconds: float,
    robot: Robot | None = None,
    tick: Callable[[str, int, int], None] | None = None,
) -> WalkMapResult:
    """Walks one repertoire trial's chosen cells and logs its walk map; returns it.

    The run's walk-map lease (`orchestrator.lease`) is held throughout, so a second walk
    map of the same run is refused instead of logging a map without this one's rows.

    Args:
        run: runs the build and walk tasks (`run_in_process`, or `run_on_ray` bound to a
            cluster).
        resume: complete the map the run already has; a complete map is returned as it
            is, nothing logged.
        restart: walk the map anew, replacing the run's (a damaged one, say).
        robot: the robot walked (default: the study's robot); tagged on the run.
        tick: called as tasks end with ("building legs", cells built, cells), then with
            ("walking", pairs done, pairs); a (cell, floor) pair is done when its row is
            known (a cell that is not walked, as it is built).

    Raises:
        WalkMapError: the run has a walk map and neither `resume` nor `restart` is on.
        Busy: another process is making this run's walk map.
        ArtefactError: the run's repertoire, or (resuming) its walk map, is damaged.
    """
    from linkevo.orchestrator.lease import Lease, Subject

    robot = robot or Robot()
    lease = Lease.take(store, Subject.walk_map(trial.run_id, trial.trial_key))
    try:
        check_before_walking(store, trial, resume, restart, robot, leased=True)
        store.set_tag(trial.run_id, layout.WALK_MAP_ROBOT, robot_tag(robot))
        with tempfile.TemporaryDirectory(prefix="linkevo-walkmap-") as tmp:
            table = store.repertoire(trial.run_id, Path(tmp) / "in")
            done = None if restart else store.walk_map(trial.run_id, Path(tmp) / "done")
            chosen = selection.choose(table, trial.mode)
            batches = plan(
                chosen,
                trial.mode,
                floors,
                done,
                as_evolved=selection.kind == "all",
                seconds=seconds,
            )
            if done is not None and not batches:
                return WalkMapResult(done, walked=False)
            kept = [] if done is None else [done[done["status"] != Status.FAILED]]
            rows: list[dict] = []
            total = sum(len(b.cells) * len(b.floors) for b in batches)
            cells, built = sum(len(b.cells) for b in batches), 0
            last = time.monotonic()
            try:
                for n_built, new_rows in walk_rows(run, batches, seconds, robot):
                    rows += new_rows
                    built += n_built
                    if tick is not None and built < cells:
                        tick("building legs", built, cells)
                    elif tick is not None:
                        tick("walking", len(rows), total)
                    if time.monotonic() - last > CHECKPOINT_S:
                        _log(store, trial, table, kept, rows, Path(tmp), picture=False)
                        last = time.monotonic()
            finally:
                frame = _log(store, trial, table, kept, rows, Path(tmp), picture=True)
    finally:
        lease.release()
    return WalkMapResult(frame, walked=True)


def _log(
    store: RunStore,
    trial: TrialRun,
    table: pd.DataFrame,
    kept: list[pd.DataFrame],
    rows: list[dict],
    tmp: Path,
    *,
    picture: bool,
) -> pd.DataFrame:
    """Logs the walk map so far (rows kept from before and walked now) to the trial's run;
    returns it."""
    new = walk_map_frame(rows)
    frame = pd.concat([*[k[list(COLUMNS)] for k in kept], new], ignore_index=True)
    frame = frame.astype(new.dtypes.to_dict())  # an empty part leaves object columns
    frame = frame.drop_duplicates(["cell", "floor"], keep="last").sort_values(["floor", "cell"])
    bins = bin_columns(table.columns)
    frame = frame.merge(table[["cell", *bins]], on="cell", how="left").reset_index(drop=True)
    path = tmp / layout.WALK_MAP
    write_parquet_atomic(path, {c: frame[c].to_numpy() for c in frame.columns})
    store.log_artefact(trial.run_id, path)
    if picture and not frame.empty:
        from linkevo.workers.plots.walk_map_figure import draw_walk_map

        png = draw_walk_map(frame, trial.approach, trial.trial_key, tmp / layout.WALK_MAP_PNG)
        store.log_artefact(trial.run_id, png)
    walked = frame[frame["status"] == Status.WALKED]
    for floor, part in walked.groupby("floor"):
        distances = part.loc[~part["breaks"], "mean_distance_cm"].to_numpy(dtype=float)
        best = float(np.nanmax(distances)) if np.isfinite(distances).any() else math.nan
        if math.isfinite(best):
            store.log_metric(trial.run_id, f"walk_best_cm_{floor}", best)
        store.log_metric(trial.run_id, f"walk_cells_{floor}", float(len(part)))
    return frame


TOP_WALKERS = 3
"""The walk map's top cells a user is shown (`top_walkers`)."""


def top_walkers(
    frame: pd.DataFrame, repertoire: pd.DataFrame, mode: str, count: int = TOP_WALKERS
) -> list[dict]:
    """Returns the walk map's `count` best walkers with what a builder should doubt: the
    cells walked soundly on every floor of the map, by their worst floor's credited distance
    (`sim.robot.walk_rows.credited_cm`), each with its credited cm per floor, the largest
    share its walks go beyond the level-body bound and the largest share its feet slide at
    (`beyond_bound_share`, `slide_share`), whether it slides, and its leg's shape
    (`sim.robot.leg.Leg.shape`).

    Args:
        frame: the walk map (`WalkMapResult.frame`); repertoire: the trial's repertoire
            (its genomes by cell); mode: the trial's genome mode.
    """
    from linkevo.sim.robot.leg import LegError, leg_from_genome

    walked = frame[frame["status"] == Status.WALKED]
    floors = walked["floor"].unique()
    order = in_floor_order(floors)
    rows: dict[int, list[dict]] = {}
    for row in walked.to_dict("records"):
        rows.setdefault(int(row["cell"]), []).append(row)
    sound = {
        c: r for c, r in rows.items() if len(r) == len(floors) and not any(x["breaks"] for x in r)
    }
    ranked = sorted(sound, key=lambda c: (-min(credited_cm(r) for r in sound[c]), c))
    genomes = dict(zip(repertoire["cell"].astype(int), repertoire["genome"], strict=True))
    out = []
    for cell in ranked[:count]:
        try:
            shape = leg_from_genome(np.asarray(genomes[cell], float), mode).shape()
        except (KeyError, LegError):
            shape = {}
        slides = [slide_share(r) for r in sound[cell]]
        out.append(
            {
                "cell": cell,
                "credited_cm": {
                    r["floor"]: round(credited_cm(r), 1)
                    for r in sorted(sound[cell], key=lambda r: order.index(r["floor"]))
                },
                "beyond_bound_share": max(beyond_bound_share(r) for r in sound[cell]),
                "slide_share": max(slides, key=lambda v: -1 if np.isnan(v) else v),
                "slides": any(v > SLIDING_SHARE for v in slides),
                "shape": shape,
            }
        )
    return out
