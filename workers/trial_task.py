"""Provides the Ray trial task: one grid trial as a nested MLflow run, evaluated in the task
with numba threads or by evaluator actors."""

from __future__ import annotations

import contextlib
import shutil
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numba
import ray
from mlflow.entities import Run

from linkevo.workers.evaluators import Evaluator, make_evaluator
from linkevo.workers.seed_repertoire import SEED_DIR, fetch_seed, read_seed
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.mlflow_recorder import MlflowRecorder
from linkevo.workers.store.outage import OUTAGE_LIMIT_S, ServerLost, patiently, use_quick_http
from linkevo.workers.store.runs import RunStore
from linkevo.workers.trial import run_trial
from linkevo.workers.trial_spec import TrialSpec

RETRYABLE_ERRORS: tuple[type[BaseException], ...] = (
    ray.exceptions.RayActorError,
    ray.exceptions.ActorUnavailableError,
    ray.exceptions.ObjectLostError,
    ray.exceptions.WorkerCrashedError,
    ray.exceptions.NodeDiedError,
)
"""Failures of the machinery, not of the trial: a trial task that meets one ends its run
KILLED and raises it; the driver then runs the trial again (`max_retries`)."""
SPEC_PARAMS: tuple[str, ...] = (
    "approach",
    "fitness",
    "mode",
    "evaluations",
    "batch_size",
    "n_angles",
    "target",
)
"""The TrialSpec fields logged as params of every trial run (and `walks`, a walking
trial's). The seed is a tag only: as a param, the MLflow UI's charts would plot it as a
number (`3900000000.00000`)."""


@dataclass(frozen=True)
class TrialJob:
    """Everything a trial task needs, resolved by the driver.

    Attributes:
        tracking_uri: absolute MLflow tracking URI.
        experiment_id: the grid's experiment.
        parent_run_id: the grid's parent run.
        grid_id: the grid id.
        trial_key: e.g. "MAP-LIS/Fp/03".
        trial_index: the trial's index within its cell.
        spec: the trial to run.
        out_dir: absolute folder for the trial's files and checkpoints.
        evaluators: evaluator actors (K); 0: the task evaluates itself.
        cpus_per_evaluator: CPUs each actor reserves.
        threads: numba threads the task evaluates with when K = 0.
        outage_s: how long the trial waits for a silent tracking server
            (`workers.store.outage`).
    """

    tracking_uri: str
    experiment_id: str
    parent_run_id: str
    grid_id: str
    trial_key: str
    trial_index: int
    spec: TrialSpec
    out_dir: str
    evaluators: int
    cpus_per_evaluator: float
    threads: int = 1
    outage_s: float = OUTAGE_LIMIT_S

    def tags(self) -> dict[str, str]:
        """Returns the tags of the trial's MLflow run (host and Ray node: where it runs)."""
        return {
            layout.PARENT: self.parent_run_id,
            layout.KIND: layout.TRIAL,
            layout.GRID_ID: self.grid_id,
            layout.TRIAL_KEY: self.trial_key,
            layout.APPROACH: self.spec.approach,
            layout.FITNESS: self.spec.fitness,
            layout.SEED: str(self.spec.seed),
            layout.TRIAL_INDEX: str(self.trial_index),
            layout.HOST: socket.gethostname(),
            layout.RAY_NODE: ray.get_runtime_context().get_node_id(),
        }


@dataclass(frozen=True)
class TrialOutcome:
    """How one trial ended.

    Attributes:
        trial_key: the trial.
        status: "FINISHED" or "FAILED".
        run_id: its MLflow run.
        best_loss: the final best (first-objective) loss, when the run logged one.
        evaluations: evaluations done, when the run logged them.
        seconds: wall time of this attempt.
        error: the failure message ("" when FINISHED).
        stopped_by: "budget", or "max_seconds" for a trial cut short by its time limit.
        coverage: the final coverage, when the run logged one.
        qd_score: the final QD-score, when the run logged one.
    """

    trial_key: str
    status: str
    run_id: str
    best_loss: float | None
    evaluations: int | None
    seconds: float
    error: str = ""
    stopped_by: str = "budget"
    coverage: float | None = None
    qd_score: float | None = None


def outcome_of(run: Run, seconds: float = 0.0) -> TrialOutcome:
    """Returns the outcome a finished or failed trial run records."""
    metrics = run.data.metrics
    evaluations = metrics.get("evaluations")
    return TrialOutcome(
        trial_key=run.data.tags[layout.TRIAL_KEY],
        status=run.info.status,
        run_id=run.info.run_id,
        best_loss=metrics.get("best_loss"),
        evaluations=None if evaluations is None else int(evaluations),
        seconds=seconds,
        error=run.data.tags.get(layout.ERROR, ""),
        stopped_by=run.data.tags.get(layout.STOPPED_BY, "budget"),
        coverage=metrics.get("coverage"),
        qd_score=metrics.get("qd_score"),
    )


def _flush_quietly(recorder: MlflowRecorder) -> None:
    # The trial already failed; its own error is the one to report.
    with contextlib.suppress(Exception):
        recorder.flush()


T = TypeVar("T")


def run_trial_job(job: TrialJob) -> TrialOutcome:
    """Runs one trial as a nested MLflow run; the body of the Ray trial task.

    A trial already FINISHED (an earlier attempt that ended just before its node died) is
    returned as is; an earlier attempt left RUNNING is marked KILLED. The trial resumes
    from its checkpoint in `job.out_dir` when one exists, replaying the checkpointed
    metrics into the new run. A trial error ends the run FAILED
    and is returned, not raised; a lost actor ends it KILLED and is raised so the driver
    retries.
    A run that a resuming driver marked KILLED meanwhile is not marked FINISHED.
    """
    use_quick_http()
    store = RunStore(job.tracking_uri, experiment_id=job.experiment_id)

    def wait(call: Callable[[], T]) -> T:  # a silent server is waited for, within a limit
        return patiently(call, job.tracking_uri, job.outage_s)

    earlier = wait(lambda: store.trial_runs(job.grid_id, trial_key=job.trial_key))
    for run in earlier:
        if run.info.status == "FINISHED":
            return outcome_of(run)
    for run in earlier:
        if run.info.status == "RUNNING":
            wait(lambda r=run: store.end_run(r.info.run_id, "KILLED", "superseded by a retry"))
    run_id = wait(lambda: store.create_run(job.trial_key, job.tags()))
    spec_values = job.spec.to_dict()
    names = SPEC_PARAMS + (("walks", "surrogate") if job.spec.walking_trial else ())
    names += ("walk_model",) if job.spec.walk_model else ()
    wait(lambda: store.log_params(run_id, {k: spec_values[k] for k in names}))
    start = time.monotonic()
    evaluator: Evaluator | None = None
    recorder = store.recorder(run_id, job.outage_s)
    try:
        out_dir = Path(job.out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        spec = job.spec
        if job.evaluators == 0:
            numba.set_num_threads(min(job.threads, numba.config.NUMBA_NUM_THREADS))
        head_start = None
        if spec.walk_model:
            from linkevo.workers.store.walk_models import load_model  # torch: only when asked

            head_start = wait(lambda: load_model(store, spec.walk_model)[0])
        evaluator = make_evaluator(
            spec,
            actors=job.evaluators,
            cpus_per_actor=job.cpus_per_evaluator,
            placement_group=ray.util.get_current_placement_group() if job.evaluators else None,
            head_start=head_start,
        )
        seed = None
        if spec.seed_from:
            folder = wait(lambda: fetch_seed(store, spec.seed_from, out_dir / SEED_DIR))
            seed = read_seed(folder, spec.seed_from)
        result = run_trial(spec, evaluator, recorder, out_dir, resume=True, seed=seed)
        wait(lambda: store.set_tag(run_id, layout.STOPPED_BY, result.stopped_by))
    except ServerLost:
        raise  # nothing can be written; the driver stops the grid, --resume marks the run
    except RETRYABLE_ERRORS as exc:
        _flush_quietly(recorder)
        message = layout.error_text(exc)
        wait(lambda: store.end_run(run_id, "KILLED", message))
        raise
    except Exception as exc:
        _flush_quietly(recorder)
        message = layout.error_text(exc)
        wait(lambda: store.end_run(run_id, "FAILED", message))
        return outcome_of(wait(lambda: store.run(run_id)), time.monotonic() - start)
    finally:
        if evaluator is not None:
            evaluator.close()
    if wait(lambda: store.status(run_id)) == "RUNNING":
        wait(lambda: store.end_run(run_id, "FINISHED"))
        # MLflow holds the finished trial's files now; the local copy (checkpoint
        # included) would only double the grid's disk use.
        shutil.rmtree(job.out_dir, ignore_errors=True)
    return outcome_of(wait(lambda: store.run(run_id)), time.monotonic() - start)
