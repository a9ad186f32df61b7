"""Real trials in a real store, recorded as a grid records them, for the tests that read
repertoires back (`explore`, `walkmap`)."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

from mlflow.entities import Param
from mlflow.tracking import MlflowClient

from linkevo.workers.evaluators import LocalEvaluator
from linkevo.workers.store.mlflow_recorder import MlflowRecorder
from linkevo.workers.store.tracking import ensure_experiment
from linkevo.workers.trial import run_trial
from linkevo.workers.trial_spec import TrialSpec
from linkevo.workers.trial_task import SPEC_PARAMS


def record_trials(root: Path, grid: str, specs: list[TrialSpec]) -> tuple[str, dict[str, str]]:
    """Runs each spec (trial index 0 of its approach and fitness) with the trial loop into
    a sqlite store under `root`, under a grid parent run; returns (the store's URI, run id
    per approach)."""
    uri = f"sqlite:///{root / 'mlflow.db'}"
    experiment = ensure_experiment(uri)
    client = MlflowClient(uri)
    client.create_run(experiment, tags={"grid_id": grid, "linkevo.kind": "grid"})
    runs = {}
    for spec in specs:
        key = f"{spec.approach}/{spec.fitness}/00"
        tags = {
            "grid_id": grid,
            "linkevo.kind": "trial",
            "approach": spec.approach,
            "fitness": spec.fitness,
            "trial_key": key,
            "trial_index": "0",
        }
        run_id = client.create_run(experiment, run_name=key, tags=tags).info.run_id
        values = asdict(spec)
        client.log_batch(run_id, params=[Param(k, str(values[k])) for k in SPEC_PARAMS])
        evaluator = LocalEvaluator(spec.eval_fitness, spec.mode, spec.target, spec.n_angles)
        run_trial(spec, evaluator, MlflowRecorder(client, run_id), root / key.replace("/", "_"))
        client.set_terminated(run_id)
        runs[spec.approach] = run_id
    return uri, runs
