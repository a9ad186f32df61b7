"""MAP-AU through the one trial loop: metrics.csv columns and exact resume after a crash."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest
import torch

from linkevo.workers.evaluators import LocalEvaluator
from linkevo.workers.recorders import NullRecorder
from linkevo.workers.trial import run_trial
from linkevo.workers.trial_spec import TrialSpec

BATCH = 200
OPTIONS = {
    "initial_epochs": 4,
    "retrain_epochs": 2,
    "retrain_period": 2,
    "ae_batch_size": 64,
    "learning_rate": 0.01,
}


def read_rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def spec() -> TrialSpec:
    return TrialSpec(
        approach="MAP-AU",
        fitness="Fp",
        evaluations=6 * BATCH,
        batch_size=BATCH,
        seed=4,
        checkpoint_every=2,
        options=OPTIONS,
    )


def test_map_au_trial_reports_training_and_resumes_exactly(
    spec: TrialSpec, tmp_path, crashing_evaluator
) -> None:
    evaluator = LocalEvaluator(spec.eval_fitness, spec.mode, spec.target, spec.n_angles)
    run_trial(spec, evaluator, NullRecorder(), tmp_path / "whole")
    whole = read_rows(tmp_path / "whole" / "metrics.csv")
    assert len(whole) == 6
    # Trainings after the initial batch and after children batches 2 and 4 (rows 3, 5).
    trained = [float(r["train_paths"]) > 0 for r in whole]
    assert trained == [True, False, True, False, True, False]
    for row, did in zip(whole, trained, strict=True):
        assert (row["recon_loss"] != "nan") == did
    assert [r["elites_dropped"] != "nan" for r in whole] == [False, False, True, False, True, False]

    with pytest.raises(RuntimeError, match="evaluator crashed"):
        run_trial(spec, crashing_evaluator(evaluator, fail_at=6), NullRecorder(), tmp_path / "cut")
    result = run_trial(spec, evaluator, NullRecorder(), tmp_path / "cut", resume=True)
    assert result.iterations == 6
    assert read_rows(tmp_path / "cut" / "metrics.csv") == whole
    assert (tmp_path / "cut" / "repertoire.parquet").read_bytes() == (
        tmp_path / "whole" / "repertoire.parquet"
    ).read_bytes()
    final = torch.load(tmp_path / "whole" / "encoder.pt", weights_only=True)
    resumed = torch.load(tmp_path / "cut" / "encoder.pt", weights_only=True)
    assert (tmp_path / "cut" / "checkpoint" / "encoder.pt").is_file()
    assert final.keys() == resumed.keys()
    for name, value in final.items():
        assert torch.equal(value, resumed[name]), name
