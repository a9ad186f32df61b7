"""Provides launch(): runs a grid's trials on Ray, tracked as nested MLflow runs."""

from __future__ import annotations

import os
import socket
import statistics
import sys
import time
import urllib.error
import urllib.request
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from mlflow.entities import Param
from mlflow.tracking import MlflowClient

from orchestrator.config import ConfigError, GridConfig, flatten, to_toml
from orchestrator.grid import Grid, TrialCell
from workers.tracking import ensure_experiment, resolve_tracking_uri
from workers.trial import TrialSpec
from workers.trial_task import TrialJob, TrialOutcome, end_run, outcome_of, trial_runs

LOCAL_OBJECT_STORE_BYTES = 512 * 1024**2
"""Object store of a Ray instance the driver starts itself: the trial objects are small."""
PROGRESS_POLL_SECONDS = 5.0
"""How often the progress view reads the running trials' evaluation counts from MLflow."""


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


def describe(grid: Grid) -> str:
    """Returns the dry-run text: resolved config, grid id, reservation and every trial."""
    cfg = grid.config
    lines = [
        to_toml(cfg).rstrip(),
        "",
        f"grid {grid.grid_id}  code {grid.code_version}  {len(grid.cells)} trials",
        f"each trial reserves {cfg.per_trial_cpus():g} CPU "
        f"({cfg.evaluators_per_trial} evaluator actor(s) x {cfg.cpus_per_evaluator:g} CPU"
        f" + {cfg.trial_cpus:g} for the trial loop)",
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
        return run_id
    tags = {
        "linkevo.kind": "grid",
        "grid_id": grid.grid_id,
        "code_version": grid.code_version,
        "host": socket.gethostname(),
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

    from sim import evaluate, random_genomes

    evaluate(random_genomes(np.random.default_rng(0), 2))


def _connect_ray(address: str | None) -> bool:
    """Connects to Ray; returns True when this call started (and must stop) it.

    An explicit address or RAY_ADDRESS joins that cluster; otherwise a new local
    instance starts (a running `ray start` cluster is joined only with `--address auto`).
    """
    import ray

    if ray.is_initialized():
        return False
    if address or os.environ.get("RAY_ADDRESS"):
        ray.init(address=address)
    else:
        ray.init(
            address="local",
            include_dashboard=False,
            object_store_memory=LOCAL_OBJECT_STORE_BYTES,
        )
    return True


def _check_fits(config: GridConfig) -> int:
    """Returns how many trials may run at once; raises when one trial cannot fit at all."""
    import ray

    nodes = [n for n in ray.nodes() if n.get("Alive")]
    total = sum(n["Resources"].get("CPU", 0.0) for n in nodes)
    largest = max((n["Resources"].get("CPU", 0.0) for n in nodes), default=0.0)
    biggest_bundle = max(config.cpus_per_evaluator, config.trial_cpus)
    if config.per_trial_cpus() > total or biggest_bundle > largest:
        raise ConfigError(
            f"one trial reserves {config.per_trial_cpus():g} CPU (evaluators_per_trial="
            f"{config.evaluators_per_trial}, cpus_per_evaluator={config.cpus_per_evaluator:g},"
            f" trial_cpus={config.trial_cpus:g}) but the Ray cluster has {total:g} CPU "
            f"(largest node {largest:g}); allowed: a reservation that fits the cluster"
        )
    if config.max_concurrent_trials:
        return config.max_concurrent_trials
    return max(1, int(total // config.per_trial_cpus()))


def _bundles(config: GridConfig) -> list[dict[str, float]]:
    """Returns a trial's placement-group bundles: the trial task's own (if it reserves
    CPUs), then one per evaluator actor."""
    own = [{"CPU": config.trial_cpus}] if config.trial_cpus > 0 else []
    return own + [{"CPU": config.cpus_per_evaluator}] * config.evaluators_per_trial


def trial_specs(grid: Grid) -> dict[str, TrialSpec]:
    """Returns every trial's spec by key, checking each approach's options by building
    its optimizer once; raises ConfigError before any trial starts."""
    from workers.trial import build_optimizer

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
            evaluators=grid.config.evaluators_per_trial,
            cpus_per_evaluator=grid.config.cpus_per_evaluator,
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
        self._grid_id = grid.grid_id
        self._start_ms = int(time.time() * 1000)
        self._start = time.monotonic()
        self._last_poll = 0.0
        self._rate = 0.0
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
        runs = trial_runs(self._ctx.client, self._ctx.experiment_id, self._grid_id)
        evaluations = sum(
            r.data.metrics.get("evaluations", 0.0)
            for r in runs
            if r.info.start_time >= self._start_ms
        )
        self._rate = evaluations / max(time.monotonic() - self._start, 1e-9)

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

    def close(self) -> None:
        """Closes the bar."""
        self._bar.close()


def _fan_out(
    grid: Grid, cells: list[TrialCell], ctx: _Context, progress: _Progress, limit: int
) -> dict[str, TrialOutcome]:
    """Runs `cells` as Ray trial tasks, each in its own placement group, collecting results
    with `ray.wait` as they finish; a failed trial is recorded and the others go on."""
    import ray
    from ray.util.placement_group import placement_group, remove_placement_group
    from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

    from workers.trial_task import RETRYABLE_ERRORS, run_trial_job

    cfg = grid.config
    task = ray.remote(run_trial_job)
    pending = deque(cells)
    in_flight: dict[ray.ObjectRef, tuple[TrialCell, object]] = {}
    outcomes: dict[str, TrialOutcome] = {}
    while pending or in_flight:
        while pending and len(in_flight) < limit:
            cell = pending.popleft()
            group = placement_group(_bundles(cfg), strategy="PACK")
            ref = task.options(
                num_cpus=cfg.trial_cpus,
                max_retries=cfg.max_retries,
                retry_exceptions=list(RETRYABLE_ERRORS),
                scheduling_strategy=PlacementGroupSchedulingStrategy(
                    placement_group=group, placement_group_bundle_index=0
                ),
            ).remote(ctx.job(grid, cell))
            in_flight[ref] = (cell, group)
        done, _ = ray.wait(list(in_flight), num_returns=1, timeout=1.0)
        finished = failed = 0
        for ref in done:
            cell, group = in_flight.pop(ref)
            try:
                outcome = ray.get(ref)
            except ray.exceptions.RayError as exc:
                outcome = _lost(ctx, grid.grid_id, cell, exc)
            remove_placement_group(group)
            outcomes[cell.key] = outcome
            if outcome.status == "FINISHED":
                finished += 1
            else:
                failed += 1
        progress.update(len(in_flight), finished, failed)
    return outcomes


def launch(
    grid: Grid,
    *,
    resume: bool = False,
    address: str | None = None,
    progress: bool = True,
    stream: TextIO = sys.stderr,
) -> GridResult:
    """Runs every trial of `grid` not already FINISHED and returns how each ended.

    Order: build and check every trial spec, check the tracking store, create the MLflow
    database and experiment, mark stale RUNNING runs KILLED (resume), connect to Ray and
    check the reservation fits, warm the numba kernel, log (or on resume reuse) the grid's
    parent run, fan out one task per trial.

    Args:
        grid: the grid to run.
        resume: complete an earlier launch of the same grid: skip FINISHED trials, mark
            stale RUNNING runs KILLED and rerun them (from their checkpoints).
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
    uri = resolve_tracking_uri(cfg.tracking_uri or None)
    check_tracking_uri(uri)
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
    todo = [cell for cell in grid.cells if cell.key not in finished]
    started_ray = _connect_ray(address) if todo else False
    try:
        limit = _check_fits(cfg) if todo else 0
        if todo:
            warm_kernels()
        parent_run_id = _parent_run(client, experiment_id, grid)
        ctx = _Context(uri, experiment_id, parent_run_id, work_root(cfg, uri), client, specs)
        view = _Progress(ctx, grid, len(grid.cells) - len(todo), progress, stream)
        try:
            ran = _fan_out(grid, todo, ctx, view, limit)
        except BaseException as exc:
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
    if result.failed:
        lines += ["", "failed trials:"]
        lines += [f"  {o.trial_key:<18} {o.error or o.status}" for o in result.failed]
    return "\n".join(lines)
