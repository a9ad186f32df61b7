"""Provides the fan-out: one Ray task per trial, retried when the machinery fails, stopped
as a whole by Ctrl-C or SIGTERM."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections import Counter, deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from linkevo.orchestrator.grid import Grid, TrialCell, trial_dir
from linkevo.orchestrator.progress import Progress
from linkevo.orchestrator.reservation import Reservation
from linkevo.sim.errors import LinkevoError
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.outage import ServerLost, ServerWatch, patiently
from linkevo.workers.store.runs import RunStore
from linkevo.workers.trial_spec import TrialSpec
from linkevo.workers.trial_task import TrialJob, TrialOutcome


class GridInterrupted(LinkevoError):
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
class TrialContext:
    """What every trial task of one launch shares: the store, the parent run, the trial
    folders' root, each trial's spec and the reservation."""

    store: RunStore
    parent_run_id: str
    root: Path
    specs: dict[str, TrialSpec]
    reservation: Reservation
    owns_ray: bool
    """True when this launch connected to (or started) Ray itself, and may disconnect."""
    watch: ServerWatch
    """Whether the tracking server answers (`workers.store.outage`)."""

    @property
    def uri(self) -> str:
        return self.store.uri

    @property
    def experiment_id(self) -> str:
        return self.store.experiment_id

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
            outage_s=self.watch.limit_s,
        )


def lost_trial(
    ctx: TrialContext, grid_id: str, cell: TrialCell, exc: BaseException
) -> TrialOutcome:
    """Returns the outcome of a trial whose task failed past its retries; ends its run."""
    message = layout.error_text(exc)
    runs = ctx.store.trial_runs(grid_id, trial_key=cell.key)
    for run in runs:
        if run.info.status == "RUNNING":
            ctx.store.end_run(run.info.run_id, "FAILED", message)
    run_id = runs[0].info.run_id if runs else ""
    return TrialOutcome(cell.key, "FAILED", run_id, None, None, 0.0, message)


@contextlib.contextmanager
def signals_stop_the_grid() -> Iterator[list[str]]:
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


def fan_out(
    grid: Grid,
    cells: list[TrialCell],
    ctx: TrialContext,
    progress: Progress,
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
    except (KeyboardInterrupt, ServerLost) as exc:  # SIGINT, SIGTERM, a silent server
        if ctx.owns_ray:
            ray.shutdown()
        else:
            from ray.util.placement_group import remove_placement_group

            for ref, (_, group) in in_flight.items():
                ray.cancel(ref, force=True)
                if group is not None:
                    remove_placement_group(group)
        if isinstance(exc, ServerLost):
            raise
        name = received[-1] if received else "SIGINT"
        done = sum(o.status == "FINISHED" for o in outcomes.values())
        raise GridInterrupted(name, done, len(in_flight), len(pending)) from exc
    return outcomes


def _run_tasks(
    grid: Grid,
    ctx: TrialContext,
    progress: Progress,
    task: object,
    pending: deque[TrialCell],
    in_flight: dict[object, tuple[TrialCell, object | None]],
    outcomes: dict[str, TrialOutcome],
) -> None:
    """The fan-out loop of `fan_out`: keeps `reservation.concurrent` trial tasks in flight
    and records each outcome as its task ends.

    A trial with evaluator actors runs in a placement group of its own: its task and its
    actors packed on one node, or, for a walking trial, spread over the nodes (a walked
    candidate is 0.2 core-seconds of work and a few kilobytes to send). One without is a
    plain task reserving `trial_cpus`, since creating a group costs about 0.4 s. A trial
    whose task died with the machinery (`RETRYABLE_ERRORS`: its worker, node or an
    evaluator actor lost) goes back to the front of the queue, up to `max_retries` times.
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
                spread = ctx.specs[cell.key].walking_trial  # its walks over the nodes
                group = placement_group(
                    reservation.bundles(), strategy="SPREAD" if spread else "PACK"
                )
                strategy = PlacementGroupSchedulingStrategy(
                    placement_group=group, placement_group_bundle_index=0
                )
            ref = task.options(
                num_cpus=reservation.trial_cpus, max_retries=0, scheduling_strategy=strategy
            ).remote(ctx.job(grid, cell))
            in_flight[ref] = (cell, group)
        done, rest = ray.wait(list(in_flight), num_returns=1, timeout=1.0)
        news = ctx.watch.news()
        if news:
            progress.say(news)
        ctx.watch.check()  # a server silent past its limit stops the grid here
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
                if isinstance(exc, ServerLost):  # the trial waited for the server in vain
                    raise ServerLost(exc.uri, exc.since, ctx.watch.limit_s) from None
                if isinstance(exc, RETRYABLE_ERRORS) and retries[cell.key] < cfg.max_retries:
                    retries[cell.key] += 1
                    progress.say(f"{cell.key}: {type(exc).__name__}; retry {retries[cell.key]}")
                    pending.appendleft(cell)
                    continue
                outcome = patiently(
                    lambda c=cell, e=exc: lost_trial(ctx, grid.grid_id, c, e),
                    ctx.uri,
                    ctx.watch.limit_s,
                )
            outcomes[cell.key] = outcome
            progress.ended(outcome)
            if outcome.status == "FINISHED":
                finished += 1
            else:
                failed += 1
        progress.update(len(in_flight), finished, failed)
