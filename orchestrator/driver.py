"""Provides launch(): runs a grid's trials on Ray, tracked as nested MLflow runs."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import statistics
import sys
import threading
import time
import urllib.error
import urllib.request
from collections import Counter, deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from mlflow.entities import Metric, Param
from mlflow.tracking import MlflowClient

from linkevo.orchestrator.config import ConfigError, GridConfig, flatten, to_toml
from linkevo.orchestrator.grid import Grid, TrialCell
from linkevo.orchestrator.reservation import Cluster, Reservation
from linkevo.workers.tracking import ensure_experiment, resolve_tracking_uri
from linkevo.workers.trial import TrialSpec
from linkevo.workers.trial_task import TrialJob, TrialOutcome, end_run, outcome_of, trial_runs

LOCAL_OBJECT_STORE_BYTES = 512 * 1024**2
"""Object store of a Ray instance the driver starts itself: the trial objects are small."""
PROGRESS_POLL_SECONDS = 5.0
"""How often the progress view reads the running trials' evaluation counts from MLflow."""


class GridInterrupted(Exception):
    """A SIGINT or SIGTERM stopped the grid; the in-flight trials were stopped and their
    runs marked KILLED, so `--resume` completes the grid.

    Attributes:
        signal_name: "SIGINT" or "SIGTERM".
        finished: the grid's trials FINISHED when it stopped (earlier launches' included).
        killed: trials in flight at the signal.
        waiting: trials not started yet.
    """

    def __init__(self, signal_name: str, finished: int, killed: int, waiting: int) -> None:
        super().__init__(signal_name)
        self.signal_name = signal_name
        self.finished = finished
        self.killed = killed
        self.waiting = waiting

    def __str__(self) -> str:
        return (
            f"stopped by {self.signal_name}: {self.finished} trial(s) finished, "
            f"{self.killed} in flight marked KILLED, {self.waiting} not started"
        )


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


def check_tracking_uri(uri: str, timeout: float = 5.0) -> None:
    """Raises ConfigError when an HTTP tracking server does not answer its health check."""
    if not uri.startswith(("http://", "https://")):
        return
    url = uri.rstrip("/") + "/health"
    try:
        with urllib.request.urlopen(url, timeout=timeout) as response:
            if response.status == 200:
                return
            problem = f"HTTP {response.status}"
    except (urllib.error.URLError, OSError) as exc:
        problem = str(getattr(exc, "reason", exc))
    raise ConfigError(
        f"tracking URI {uri!r} is unreachable ({url}: {problem}); start the server, or "
        "allowed: an http(s):// MLflow server that answers /health, a sqlite:/// URI, "
        "or a folder for an embedded store"
    )


def work_root(config: GridConfig, tracking_uri: str) -> Path:
    """Returns the folder holding `trials/<grid_id>/...`: `work_dir`, else the embedded
    store's folder, else `./runs`."""
    if config.work_dir:
        return Path(config.work_dir).expanduser().resolve()
    if tracking_uri.startswith("sqlite:///"):
        return Path(tracking_uri.removeprefix("sqlite:///")).parent
    return Path("runs").resolve()


def trial_dir(root: Path, grid: Grid, cell: TrialCell) -> Path:
    """Returns a trial's folder for its files and checkpoints."""
    return root / "trials" / grid.grid_id / cell.dirname


def describe(grid: Grid, cluster: Cluster) -> str:
    """Returns the dry-run text: resolved config, grid id, reservation and every trial."""
    cfg = grid.config
    reservation = Reservation.plan(cfg, len(grid.cells), cluster)
    where = "this machine" if cluster.local else "the Ray cluster"
    lines = [
        to_toml(cfg).rstrip(),
        "",
        f"grid {grid.grid_id}  code {grid.code_version}  {len(grid.cells)} trials",
        f"on {where} ({cluster.total_cpus:g} CPU): {reservation.describe()}",
        "",
        f"{'trial key':<20} {'seed':>10}",
    ]
    lines += [f"{cell.key:<20} {cell.seed:>10}" for cell in grid.cells]
    return "\n".join(lines)


def _parent_run(client: MlflowClient, experiment_id: str, grid: Grid) -> str:
    """Returns the grid's parent run id, reusing an earlier launch's run on resume."""
    existing = client.search_runs(
        [experiment_id],
        f"tags.grid_id = '{grid.grid_id}' and tags.`linkevo.kind` = 'grid'",
        max_results=1,
        order_by=["attributes.start_time ASC"],
    )
    if existing:
        run_id = existing[0].info.run_id
        client.update_run(run_id, status="RUNNING")
        if "error" in existing[0].data.tags:  # the error of a launch that is over
            client.delete_tag(run_id, "error")
        return run_id
    tags = {
        "linkevo.kind": "grid",
        "grid_id": grid.grid_id,
        "code_version": grid.code_version,
        "host": socket.gethostname(),
        "mlflow.note.content": grid_description(grid),
    }
    run_id = client.create_run(experiment_id, run_name=f"grid-{grid.grid_id}", tags=tags)
    run_id = run_id.info.run_id
    params = [Param(k, v) for k, v in flatten(grid.config.to_dict()).items()]
    for start in range(0, len(params), 100):
        client.log_batch(run_id, params=params[start : start + 100])
    client.log_dict(run_id, grid.config.to_dict(), "grid_config.json")
    client.log_text(run_id, to_toml(grid.config), "grid_config.toml")
    return run_id


def warm_kernels() -> None:
    """Compiles (or loads) the numba simulation kernel once in the driver, so that its
    on-disk cache is written before the evaluator actors start instead of every new actor
    compiling it at the same time."""
    import numpy as np

    from linkevo.sim import evaluate, random_genomes

    evaluate(random_genomes(np.random.default_rng(0), 2))


def uses_local_ray(address: str | None) -> bool:
    """Returns True when the driver starts its own Ray instance (no address, no RAY_ADDRESS)."""
    return not (address or os.environ.get("RAY_ADDRESS"))


def dry_run_cluster(address: str | None) -> Cluster:
    """Returns the cluster a grid would run on: this machine for a local instance (nothing
    starts), else the running cluster's CPUs (joined, read, left)."""
    if uses_local_ray(address):
        return Cluster.this_machine()
    import ray

    started = _connect_ray(address, Cluster.this_machine())
    try:
        return Cluster.of_ray()
    finally:
        if started:
            ray.shutdown()


def _connect_ray(address: str | None, cluster: Cluster) -> bool:
    """Connects to Ray; returns True when this call started (and must stop) it.

    An explicit address or RAY_ADDRESS joins that cluster; otherwise a new local
    instance starts with `cluster`'s CPUs (a running `ray start` cluster is joined only
    with `--address auto`).
    """
    import ray

    if ray.is_initialized():
        return False
    in_main = threading.current_thread() is threading.main_thread()
    before = signal.getsignal(signal.SIGTERM) if in_main else None
    if not uses_local_ray(address):
        ray.init(address=address)
    else:
        ray.init(
            address="local",
            num_cpus=int(cluster.total_cpus),
            include_dashboard=False,
            object_store_memory=LOCAL_OBJECT_STORE_BYTES,
        )
    if in_main:
        # ray.init installs SIGTERM handlers (a native one that dumps a stack, a Python
        # one that exits); give the signal back to the handler this process had
        # (`_signals_stop_the_grid` installs the grid's own around the fan-out).
        signal.signal(signal.SIGTERM, before)
    return True


def trial_specs(grid: Grid) -> dict[str, TrialSpec]:
    """Returns every trial's spec by key, checking each approach's options by building
    its optimizer once; raises ConfigError before any trial starts."""
    from linkevo.workers.trial import build_optimizer

    cfg = grid.config
    specs: dict[str, TrialSpec] = {}
    for cell in grid.cells:
        try:
            spec = TrialSpec(
                approach=cell.approach,
                fitness=cell.fitness,
                evaluations=cfg.evaluations,
                batch_size=cfg.batch_size,
                mode=cfg.mode,
                seed=cell.seed,
                target=cfg.target,
                n_angles=cfg.n_angles,
                checkpoint_every=cfg.checkpoint_every,
                max_seconds=cfg.max_seconds,
                options=dict(cfg.options.get(cell.approach, {})),
            )
            if cell.index == 0:
                build_optimizer(spec)
        except ValueError as exc:
            raise ConfigError(f"trial {cell.key}: {exc}") from exc
        specs[cell.key] = spec
    return specs


@dataclass(frozen=True)
class _Context:
    uri: str
    experiment_id: str
    parent_run_id: str
    root: Path
    client: MlflowClient
    specs: dict[str, TrialSpec]
    reservation: Reservation
    owns_ray: bool
    """True when this launch connected to (or started) Ray itself, and may disconnect."""

    def job(self, grid: Grid, cell: TrialCell) -> TrialJob:
        """Returns the trial task's input for one cell."""
        return TrialJob(
            tracking_uri=self.uri,
            experiment_id=self.experiment_id,
            parent_run_id=self.parent_run_id,
            grid_id=grid.grid_id,
            trial_key=cell.key,
            trial_index=cell.index,
            spec=self.specs[cell.key],
            out_dir=str(trial_dir(self.root, grid, cell)),
            evaluators=self.reservation.evaluators,
            cpus_per_evaluator=self.reservation.cpus_per_evaluator,
            threads=self.reservation.threads,
        )


def _lost(ctx: _Context, grid_id: str, cell: TrialCell, exc: BaseException) -> TrialOutcome:
    """Returns the outcome of a trial whose task failed past its retries; ends its run."""
    message = f"{type(exc).__name__}: {exc}"
    runs = trial_runs(ctx.client, ctx.experiment_id, grid_id, trial_key=cell.key)
    for run in runs:
        if run.info.status == "RUNNING":
            end_run(ctx.client, run.info.run_id, "FAILED", message)
    run_id = runs[0].info.run_id if runs else ""
    return TrialOutcome(cell.key, "FAILED", run_id, None, None, 0.0, message[:500])


class _Progress:
    """The live view on stderr: trials done / running / failed and evaluations per second."""

    def __init__(self, ctx: _Context, grid: Grid, done: int, enabled: bool, stream: TextIO):
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
        # in proportion to the grid on the tracking server (docs/scale.md).
        runs = trial_runs(
            self._ctx.client, self._ctx.experiment_id, self._grid_id, status="RUNNING"
        )
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


@contextlib.contextmanager
def _signals_stop_the_grid() -> Iterator[list[str]]:
    """Makes SIGTERM raise the KeyboardInterrupt a Ctrl-C raises, so both stop the grid the
    same way; yields the names of the signals received (in the main thread; elsewhere the
    handlers stay as they are and the list stays empty).

    The names are kept here because Ray re-raises an interrupt met inside its calls
    without the exception's message.
    """
    received: list[str] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return

    def interrupt(signum: int, frame: object) -> None:
        received.append(signal.Signals(signum).name)
        raise KeyboardInterrupt(received[-1])

    before = {s: signal.signal(s, interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield received
    finally:
        for signum, handler in before.items():
            signal.signal(signum, handler)


def _fan_out(
    grid: Grid,
    cells: list[TrialCell],
    ctx: _Context,
    progress: _Progress,
    received: list[str],
) -> dict[str, TrialOutcome]:
    """Runs `cells` as Ray trial tasks, collecting results with `ray.wait` as they finish;
    a failed trial is recorded and the others go on. `received` names the signals
    received so far (the last one names an interrupt).

    On an interrupt the trials in flight are stopped before their runs are marked KILLED:
    a driver that connected to Ray itself disconnects, and Ray kills the tasks (and their
    actors) of a driver that left; within a caller's Ray session they are cancelled.
    Disconnecting is preferred because a `ray.cancel` that meets a task's reply on its way
    back aborts the driver inside Ray ("Tried to complete task that was not pending").
    """
    import ray

    from linkevo.workers.trial_task import run_trial_job

    task = ray.remote(run_trial_job)
    pending = deque(cells)
    in_flight: dict[ray.ObjectRef, tuple[TrialCell, object | None]] = {}
    outcomes: dict[str, TrialOutcome] = {}
    try:
        _run_tasks(grid, ctx, progress, task, pending, in_flight, outcomes)
    except KeyboardInterrupt as exc:  # SIGINT or SIGTERM (_signals_stop_the_grid)
        if ctx.owns_ray:
            ray.shutdown()
        else:
            from ray.util.placement_group import remove_placement_group

            for ref, (_, group) in in_flight.items():
                ray.cancel(ref, force=True)
                if group is not None:
                    remove_placement_group(group)
        name = received[-1] if received else "SIGINT"
        done = sum(o.status == "FINISHED" for o in outcomes.values())
        raise GridInterrupted(name, done, len(in_flight), len(pending)) from exc
    return outcomes


def _run_tasks(
    grid: Grid,
    ctx: _Context,
    progress: _Progress,
    task: object,
    pending: deque[TrialCell],
    in_flight: dict[object, tuple[TrialCell, object | None]],
    outcomes: dict[str, TrialOutcome],
) -> None:
    """The fan-out loop of `_fan_out`: keeps `reservation.concurrent` trial tasks in flight
    and records each outcome as its task ends.

    A trial with evaluator actors runs in a placement group of its own (its task and its
    actors are placed together); one without is a plain task reserving `trial_cpus`, since
    creating a group costs about 0.4 s. A trial whose task died with the machinery
    (`RETRYABLE_ERRORS`: its worker, node or an evaluator actor lost) goes back to the
    front of the queue, up to `max_retries` times.
    """
    import ray
    from ray.util.placement_group import placement_group, remove_placement_group
    from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

    from linkevo.workers.trial_task import RETRYABLE_ERRORS

    cfg = grid.config
    reservation = ctx.reservation
    retries: Counter[str] = Counter()
    while pending or in_flight:
        while pending and len(in_flight) < reservation.concurrent:
            cell = pending.popleft()
            group = strategy = None
            if reservation.evaluators:
                group = placement_group(reservation.bundles(), strategy="PACK")
                strategy = PlacementGroupSchedulingStrategy(
                    placement_group=group, placement_group_bundle_index=0
                )
            ref = task.options(
                num_cpus=reservation.trial_cpus, max_retries=0, scheduling_strategy=strategy
            ).remote(ctx.job(grid, cell))
            in_flight[ref] = (cell, group)
        done, rest = ray.wait(list(in_flight), num_returns=1, timeout=1.0)
        if done and rest:  # every trial that has ended, not one per pass
            done += ray.wait(rest, num_returns=len(rest), timeout=0)[0]
        finished = failed = 0
        for ref in done:
            cell, group = in_flight.pop(ref)
            if group is not None:
                remove_placement_group(group)
            try:
                outcome = ray.get(ref)
            except ray.exceptions.RayError as exc:
                if isinstance(exc, RETRYABLE_ERRORS) and retries[cell.key] < cfg.max_retries:
                    retries[cell.key] += 1
                    progress.say(f"{cell.key}: {type(exc).__name__}; retry {retries[cell.key]}")
                    pending.appendleft(cell)
                    continue
                outcome = _lost(ctx, grid.grid_id, cell, exc)
            outcomes[cell.key] = outcome
            progress.ended(outcome)
            if outcome.status == "FINISHED":
                finished += 1
            else:
                failed += 1
        progress.update(len(in_flight), finished, failed)


def check_restart(grid: Grid, restart: tuple[str, ...], resume: bool) -> None:
    """Raises ConfigError for a `--restart-trial` key the grid lacks, or without resume."""
    if not restart:
        return
    if not resume:
        raise ConfigError("--restart-trial needs --resume: it restarts a trial of a grid")
    keys = {cell.key for cell in grid.cells}
    for key in restart:
        if key not in keys:
            raise ConfigError(
                f"--restart-trial {key!r}: not a trial of grid {grid.grid_id}; allowed: a "
                f"trial key APPROACH/FITNESS/INDEX such as {grid.cells[0].key}"
            )


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
    else the cluster's, once connected), create the MLflow database and experiment, mark
    stale RUNNING runs KILLED (resume), plan the reservation for the trials left
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
    """
    start = time.monotonic()
    cfg = grid.config
    specs = trial_specs(grid)
    check_restart(grid, restart, resume)
    uri = resolve_tracking_uri(cfg.tracking_uri or None)
    check_tracking_uri(uri)
    local = uses_local_ray(address)
    if local:  # a local instance starts later, with this machine's CPUs
        cluster = Cluster.this_machine()
        started_ray = False
    else:
        started_ray = _connect_ray(address, Cluster.this_machine())
        cluster = Cluster.of_ray()
    try:
        Reservation.plan(cfg, len(grid.cells), cluster)  # refuses before the store is written
        experiment_id = ensure_experiment(uri, cfg.experiment)
        client = MlflowClient(uri)
        earlier = trial_runs(client, experiment_id, grid.grid_id)
        if earlier and not resume:
            raise ConfigError(
                f"grid {grid.grid_id} already has {len(earlier)} trial run(s) in {uri}; "
                "pass --resume to complete it, or change the config (e.g. --set seed=1)"
            )
        finished = {r.data.tags["trial_key"]: r for r in earlier if r.info.status == "FINISHED"}
        for run in earlier:
            if run.info.status == "RUNNING":
                end_run(client, run.info.run_id, "KILLED", "stale: the grid driver stopped")
        done_restarts = sorted(set(restart) & set(finished))
        if done_restarts:
            raise ConfigError(
                f"--restart-trial {', '.join(done_restarts)}: already FINISHED; a finished "
                "trial is kept (change the config for a new grid)"
            )
        root = work_root(cfg, uri)
        for cell in grid.cells:
            if cell.key in restart:
                shutil.rmtree(trial_dir(root, grid, cell), ignore_errors=True)
        todo = [cell for cell in grid.cells if cell.key not in finished]
        reservation = Reservation.plan(cfg, len(todo), cluster)
        if todo and local:
            started_ray = _connect_ray(address, cluster)
        if todo:
            warm_kernels()
        parent_run_id = _parent_run(client, experiment_id, grid)
        ctx = _Context(
            uri, experiment_id, parent_run_id, root, client, specs, reservation, started_ray
        )
        view = _Progress(ctx, grid, len(grid.cells) - len(todo), progress, stream)
        try:
            with _signals_stop_the_grid() as received:
                ran = _fan_out(grid, todo, ctx, view, received)
        except BaseException as exc:
            if isinstance(exc, GridInterrupted):
                exc.finished += len(finished)
            for run in trial_runs(client, experiment_id, grid.grid_id, status="RUNNING"):
                end_run(client, run.info.run_id, "KILLED", f"the grid driver stopped: {exc}")
            end_run(client, parent_run_id, "KILLED", f"{type(exc).__name__}: {exc}")
            raise
        finally:
            view.close()
    finally:
        if started_ray:
            import ray

            ray.shutdown()
    outcomes = tuple(
        outcome_of(finished[c.key]) if c.key in finished else ran[c.key] for c in grid.cells
    )
    status = "FINISHED" if all(o.status == "FINISHED" for o in outcomes) else "FAILED"
    log_cell_summaries(client, parent_run_id, cfg, outcomes)
    client.set_terminated(parent_run_id, status)
    return GridResult(
        grid_id=grid.grid_id,
        parent_run_id=parent_run_id,
        experiment_id=experiment_id,
        tracking_uri=uri,
        outcomes=outcomes,
        skipped=tuple(c.key for c in grid.cells if c.key in finished),
        seconds=time.monotonic() - start,
    )


def cell_summaries(config: GridConfig, outcomes: tuple[TrialOutcome, ...]) -> dict[str, float]:
    """Returns the grid parent's summary metrics: per approach and fitness, over the
    FINISHED trials, `<approach>/<fitness>/best_loss_median`, `.../best_loss_min`,
    `.../coverage_median`, `.../qd_score_median` and `.../finished` (a count)."""
    metrics: dict[str, float] = {}
    for approach in config.approaches:
        for fitness in config.fitnesses:
            cell = [
                o
                for o in outcomes
                if o.trial_key.startswith(f"{approach}/{fitness}/") and o.status == "FINISHED"
            ]
            prefix = f"{approach}/{fitness}"
            metrics[f"{prefix}/finished"] = float(len(cell))
            for name in ("best_loss", "coverage", "qd_score"):
                values = [getattr(o, name) for o in cell if getattr(o, name) is not None]
                if values:
                    metrics[f"{prefix}/{name}_median"] = float(statistics.median(values))
                if values and name == "best_loss":
                    metrics[f"{prefix}/best_loss_min"] = float(min(values))
    return metrics


def log_cell_summaries(
    client: MlflowClient, run_id: str, config: GridConfig, outcomes: tuple[TrialOutcome, ...]
) -> None:
    """Logs `cell_summaries` to the grid's parent run, so the MLflow UI's runs table shows
    each cell's numbers next to the grid (a resumed grid logs them again, updated)."""
    metrics = [
        Metric(key, value, int(time.time() * 1000), 0)
        for key, value in cell_summaries(config, outcomes).items()
    ]
    for start in range(0, len(metrics), 1000):
        client.log_batch(run_id, metrics=metrics[start : start + 1000])


def grid_description(grid: Grid) -> str:
    """Returns the parent run's description (MLflow's `mlflow.note.content`, Markdown):
    what the grid runs, its budget and how to read the results."""
    cfg = grid.config
    return (
        f"**linkevo grid `{grid.grid_id}`** ({len(grid.cells)} trials): "
        f"{', '.join(cfg.approaches)} × {', '.join(cfg.fitnesses)}, {cfg.trials} trial(s) "
        f"each; {cfg.evaluations:,} evaluations per trial in batches of {cfg.batch_size:,}; "
        f"mode `{cfg.mode}`, target `{cfg.target}`, grid seed {cfg.seed}; code "
        f"`{grid.code_version}`.\n\n"
        "The nested runs are the trials (metrics per iteration, the final repertoire or "
        "population, the best linkage). This run's metrics summarise each approach and "
        "fitness: `<approach>/<fitness>/best_loss_median`, `best_loss_min`, "
        "`coverage_median`, `qd_score_median`.\n\n"
        f"Figures and statistics: `linkevo report {grid.grid_id}` (also logged here under "
        f"`report/`). A trial's linkage: `linkevo pull RUN_ID`, or `linkevo pull "
        f"{grid.grid_id} --best --fitness {cfg.fitnesses[0]}`. Resolved config: "
        "`grid_config.toml`."
    )


def _fmt(value: float | None) -> str:
    return "-" if value is None else f"{value:.4g}"


def summary(result: GridResult, config: GridConfig) -> str:
    """Returns the end-of-grid table: per cell trials finished and best loss (min, median),
    then every failed trial with its error."""
    lines = [
        f"grid {result.grid_id}: {len(result.outcomes) - len(result.failed)}/"
        f"{len(result.outcomes)} trials finished ({len(result.skipped)} already finished "
        f"before this launch), {len(result.failed)} failed, {result.seconds:.0f} s",
        "",
        f"{'approach':<9} {'fitness':<7} {'finished':>8} {'best loss min':>14} {'median':>10}",
    ]
    for approach in config.approaches:
        for fitness in config.fitnesses:
            cell = [o for o in result.outcomes if o.trial_key.startswith(f"{approach}/{fitness}/")]
            losses = [
                o.best_loss for o in cell if o.status == "FINISHED" and o.best_loss is not None
            ]
            done = sum(o.status == "FINISHED" for o in cell)
            lines.append(
                f"{approach:<9} {fitness:<7} {f'{done}/{len(cell)}':>8} "
                f"{_fmt(min(losses) if losses else None):>14} "
                f"{_fmt(statistics.median(losses) if losses else None):>10}"
            )
    cut = [o.trial_key for o in result.outcomes if o.stopped_by == "max_seconds"]
    if cut:
        lines += [
            "",
            f"{len(cut)} trial(s) stopped by max_seconds before their budget: {', '.join(cut)}",
        ]
    if result.failed:
        lines += ["", "failed trials:"]
        lines += [f"  {o.trial_key:<18} {o.error or o.status}" for o in result.failed]
    return "\n".join(lines)
