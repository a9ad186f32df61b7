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
from typing import TextIO

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
    check_store,
    check_store_holds_grid,
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
from linkevo.workers.trial_task import TrialOutcome, end_run, outcome_of


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

    Order: build and check every trial spec, check the tracking store, check that one
    trial's reservation fits (this machine's CPUs for a local instance, before Ray starts;
    else the cluster's, once connected), create the MLflow database and experiment,
    take the grid's lease (`lease`: one driver per grid), mark stale RUNNING runs
    KILLED (resume), plan the reservation for the trials left
    (`orchestrator.reservation`), start a local Ray instance, warm the numba kernel, log
    (or on resume reuse) the grid's parent run, fan out one task per trial.

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
        client = store.client
        lease = Lease.take(client, uri, experiment_id, Subject.grid(grid.grid_id))
        earlier = store.trial_runs(grid.grid_id)
        if earlier and not resume:
            raise ConfigError(
                f"grid {grid.grid_id} already has {len(earlier)} trial run(s) in {uri}; "
                "pass --resume to complete it (or, with a larger trials, to extend it), or "
                "change the config (e.g. --set seed=1)"
            )
        check_no_shrink(grid, earlier)
        root = work_root(cfg, uri)
        if resume and not earlier:
            check_store_holds_grid(grid_record(root, grid), uri, grid)
        finished = {
            r.data.tags[layout.TRIAL_KEY]: r for r in earlier if r.info.status == "FINISHED"
        }
        for run in earlier:
            if run.info.status == "RUNNING":
                end_run(client, run.info.run_id, "KILLED", "stale: the grid driver stopped")
        done_restarts = sorted(set(restart) & set(finished))
        if done_restarts:
            raise ConfigError(
                f"--restart-trial {', '.join(done_restarts)}: already FINISHED; a finished "
                "trial is kept (change the config for a new grid)"
            )
        for cell in grid.cells:
            if cell.key in restart:
                shutil.rmtree(trial_dir(root, grid, cell), ignore_errors=True)
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
        try:
            with signals_stop_the_grid() as received:
                ran = fan_out(grid, todo, ctx, view, received)
        except BaseException as exc:
            if isinstance(exc, GridInterrupted):
                exc.finished += len(finished)
            if not isinstance(exc, ServerLost) and answers(uri):
                running = store.trial_runs(grid.grid_id, status="RUNNING")
                for run in running:
                    end_run(client, run.info.run_id, "KILLED", f"the grid driver stopped: {exc}")
                end_run(client, parent_run_id, "KILLED", layout.error_text(exc))
            elif not isinstance(exc, ServerLost | KeyboardInterrupt | GridInterrupted):
                since = watch.down_since or time.time()
                during = f"the driver ({layout.error_text(exc)})"
                raise ServerLost(uri, since, watch.limit_s, during) from exc
            raise  # a silent server cannot be written: --resume marks the runs
        finally:
            view.close()
            watch.close()
        outcomes = tuple(
            outcome_of(finished[c.key]) if c.key in finished else ran[c.key] for c in grid.cells
        )
        status = "FINISHED" if all(o.status == "FINISHED" for o in outcomes) else "FAILED"
        patiently(
            lambda: log_grid_summary(client, parent_run_id, grid, outcomes), uri, watch.limit_s
        )
        patiently(lambda: client.set_terminated(parent_run_id, status), uri, watch.limit_s)
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
