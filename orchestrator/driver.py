"""Provides launch(): runs a grid's trials on Ray, tracked as nested MLflow runs.

The phases live beside it: `ray_connection` (a local instance or a cluster), `grid_run`
(the parent run and its summaries), `fan_out` (one task per trial, retries, signals) and
`progress` (the live view); the terminal text is in `commands/grid.py`.
"""

from __future__ import annotations

import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from linkevo.orchestrator.config import ConfigError
from linkevo.orchestrator.fan_out import (
    GridInterrupted,
    TrialContext,
    fan_out,
    signals_stop_the_grid,
)
from linkevo.orchestrator.grid import Grid, grid_record, trial_dir, work_root
from linkevo.orchestrator.grid_run import log_grid_summary, parent_run
from linkevo.orchestrator.launch_checks import (
    check_no_shrink,
    check_restart,
    check_seed,
    check_store,
    check_store_holds_grid,
    check_walk_model,
    trial_specs,
)
from linkevo.orchestrator.lease import Lease, Subject
from linkevo.orchestrator.progress import Progress
from linkevo.orchestrator.ray_connection import connect_ray, uses_local_ray, warm_kernels
from linkevo.orchestrator.reservation import Cluster, Reservation
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.artifacts import write_json_atomic
from linkevo.workers.store.outage import (
    ServerLost,
    ServerWatch,
    answers,
    patiently,
    use_quick_http,
)
from linkevo.workers.store.runs import RunStore
from linkevo.workers.store.tracking import ensure_experiment, resolve_tracking_uri
from linkevo.workers.trial_task import TrialOutcome, outcome_of

if TYPE_CHECKING:
    from mlflow.entities import Run


@dataclass(frozen=True)
class GridResult:
    """How a launch ended.

    Attributes:
        grid_id: the grid.
        parent_run_id: the grid's parent MLflow run.
        experiment_id: its experiment.
        tracking_uri: the absolute tracking URI.
        outcomes: one per trial of the grid, in grid order (skipped trials included).
        skipped: keys already FINISHED before this launch (not run again).
        seconds: the launch's wall time.
    """

    grid_id: str
    parent_run_id: str
    experiment_id: str
    tracking_uri: str
    outcomes: tuple[TrialOutcome, ...]
    skipped: tuple[str, ...]
    seconds: float

    @property
    def failed(self) -> tuple[TrialOutcome, ...]:
        """The trials that did not finish."""
        return tuple(o for o in self.outcomes if o.status != "FINISHED")


def launch(
    grid: Grid,
    *,
    resume: bool = False,
    restart: tuple[str, ...] = (),
    address: str | None = None,
    progress: bool = True,
    stream: TextIO = sys.stderr,
) -> GridResult:
    """Runs every trial of `grid` not already FINISHED and returns how each ended.

    Phases: the checks (`launch_checks`: every trial spec, the store, one trial's
    reservation against this machine's CPUs for a local instance, before Ray starts, or
    the cluster's once connected), the store (database, experiment, the grid's lease:
    one driver per grid), what earlier launches left (`_settle_earlier_runs`), the
    reservation for the trials left (`orchestrator.reservation`), Ray (a local instance,
    the numba kernel warmed), the parent run (logged, or on resume reused), the trials
    (`_run_trials`: one task per trial), the parent run's end (`_end_parent_run`).

    Args:
        grid: the grid to run.
        resume: complete an earlier launch of the same grid: skip FINISHED trials, mark
            stale RUNNING runs KILLED and rerun them (from their checkpoints).
        restart: trial keys (with `resume`) whose checkpoints are discarded, so they run
            afresh (a damaged checkpoint); a FINISHED one is refused.
        address: Ray address; None honours RAY_ADDRESS, else starts a local instance.
        progress: show the live progress bar.
        stream: where the progress bar goes.

    Raises:
        ConfigError: the store is unreachable, the grid already has trial runs and
            `resume` is False, or one trial's reservation does not fit the cluster.
        Busy: another driver is running the grid.
    """
    start = time.monotonic()
    cfg = grid.config
    specs = trial_specs(grid)
    check_restart(grid, restart, resume)
    uri = resolve_tracking_uri(cfg.tracking_uri or None)
    check_store(uri)
    local = uses_local_ray(address)
    if local:  # a local instance starts later, with this machine's CPUs
        cluster = Cluster.this_machine()
        started_ray = False
    else:
        started_ray = connect_ray(address, Cluster.this_machine())
        cluster = Cluster.of_ray()
    lease = watch = None
    try:
        Reservation.plan(cfg, len(grid.cells), cluster)  # refuses before the store is written
        experiment_id = ensure_experiment(uri, cfg.experiment)
        store = RunStore(uri, cfg.experiment, experiment_id=experiment_id)
        check_seed(store, cfg.seed_from)
        check_walk_model(store, cfg.walk_model)
        lease = Lease.take(store, Subject.grid(grid.grid_id))
        root = work_root(cfg, uri)
        finished = _settle_earlier_runs(store, grid, root, resume=resume, restart=restart)
        todo = [cell for cell in grid.cells if cell.key not in finished]
        reservation = Reservation.plan(cfg, len(todo), cluster)
        if todo and local:
            started_ray = connect_ray(address, cluster)
        if todo:
            warm_kernels()
        parent_run_id = parent_run(store, grid)
        use_quick_http()  # no call waits minutes on a silent server; `watch` tells the user
        watch = ServerWatch(uri, cfg.server_outage_s)
        record = {"grid_id": grid.grid_id, "tracking_uri": uri, "parent_run_id": parent_run_id}
        grid_record(root, grid).parent.mkdir(parents=True, exist_ok=True)
        write_json_atomic(grid_record(root, grid), record)
        ctx = TrialContext(store, parent_run_id, root, specs, reservation, started_ray, watch)
        view = Progress(ctx, grid, len(grid.cells) - len(todo), progress, stream)
        ran = _run_trials(ctx, grid, todo, view, len(finished))
        outcomes = tuple(
            outcome_of(finished[c.key]) if c.key in finished else ran[c.key] for c in grid.cells
        )
        _end_parent_run(ctx, grid, outcomes)
    finally:
        if lease is not None:
            lease.release(write=watch is None or watch.down_since is None)
        if started_ray:
            import ray

            ray.shutdown()
    return GridResult(
        grid_id=grid.grid_id,
        parent_run_id=parent_run_id,
        experiment_id=experiment_id,
        tracking_uri=uri,
        outcomes=outcomes,
        skipped=tuple(c.key for c in grid.cells if c.key in finished),
        seconds=time.monotonic() - start,
    )


def _settle_earlier_runs(
    store: RunStore, grid: Grid, root: Path, *, resume: bool, restart: tuple[str, ...]
) -> dict[str, Run]:
    """Returns the grid's FINISHED trial runs by key, after settling what earlier launches
    left: refused without `resume`; a store that lost the grid refused; runs left RUNNING
    (a driver that died) marked KILLED; the folders of the `restart` trials removed.

    Raises:
        ConfigError: trial runs exist without `resume`, the grid would shrink, the store
            lost the grid, or a FINISHED trial is to be restarted.
    """
    earlier = store.trial_runs(grid.grid_id)
    if earlier and not resume:
        raise ConfigError(
            f"grid {grid.grid_id} already has {len(earlier)} trial run(s) in {store.uri}; "
            "pass --resume to complete it (or, with a larger trials, to extend it), or "
            "change the config (e.g. --set seed=1)"
        )
    check_no_shrink(grid, earlier)
    if resume and not earlier:
        check_store_holds_grid(grid_record(root, grid), store.uri, grid)
    finished = {r.data.tags[layout.TRIAL_KEY]: r for r in earlier if r.info.status == "FINISHED"}
    for run in earlier:
        if run.info.status == "RUNNING":
            store.end_run(run.info.run_id, "KILLED", "stale: the grid driver stopped")
    done_restarts = sorted(set(restart) & set(finished))
    if done_restarts:
        raise ConfigError(
            f"--restart-trial {', '.join(done_restarts)}: already FINISHED; a finished "
            "trial is kept (change the config for a new grid)"
        )
    for cell in grid.cells:
        if cell.key in restart:
            shutil.rmtree(trial_dir(root, grid, cell), ignore_errors=True)
    return finished


def _run_trials(
    ctx: TrialContext, grid: Grid, todo: list, view: Progress, finished: int
) -> dict[str, TrialOutcome]:
    """Fans the trials out (`fan_out`) and returns how each ended. Stopped by a signal or
    an error, it marks the runs in flight and the parent run KILLED where the store still
    answers, and re-raises (a silent store is left to `--resume` to mark)."""
    uri, watch = ctx.uri, ctx.watch
    try:
        with signals_stop_the_grid() as received:
            return fan_out(grid, todo, ctx, view, received)
    except BaseException as exc:
        if isinstance(exc, GridInterrupted):
            exc.finished += finished
        if not isinstance(exc, ServerLost) and answers(uri):
            for run in ctx.store.trial_runs(grid.grid_id, status="RUNNING"):
                ctx.store.end_run(run.info.run_id, "KILLED", f"the grid driver stopped: {exc}")
            ctx.store.end_run(ctx.parent_run_id, "KILLED", layout.error_text(exc))
        elif not isinstance(exc, ServerLost | KeyboardInterrupt | GridInterrupted):
            since = watch.down_since or time.time()
            during = f"the driver ({layout.error_text(exc)})"
            raise ServerLost(uri, since, watch.limit_s, during) from exc
        raise
    finally:
        view.close()
        watch.close()


def _end_parent_run(ctx: TrialContext, grid: Grid, outcomes: tuple[TrialOutcome, ...]) -> None:
    """Logs the grid's summary to its parent run and ends it FINISHED, or FAILED when a
    trial did not finish (waiting out a silent server within its limit)."""
    store, limit = ctx.store, ctx.watch.limit_s
    status = "FINISHED" if all(o.status == "FINISHED" for o in outcomes) else "FAILED"
    patiently(lambda: log_grid_summary(store, ctx.parent_run_id, grid, outcomes), ctx.uri, limit)
    patiently(lambda: store.end_run(ctx.parent_run_id, status), ctx.uri, limit)
