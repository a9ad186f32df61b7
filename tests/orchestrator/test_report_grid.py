"""End to end: a real tiny grid on a real local Ray, with one failed trial, then its report."""

from __future__ import annotations

import pandas as pd
import pytest
from mlflow.tracking import MlflowClient

from linkevo.orchestrator.driver import launch
from linkevo.orchestrator.grid import trial_dir, work_root
from linkevo.orchestrator.report import build_report
from tests.helpers.grid import tiny_grid

pytestmark = pytest.mark.ray


def test_report_of_a_real_grid_with_a_failed_trial(ray_local, tmp_path):
    grid = tiny_grid(tmp_path, fitnesses=["Fp"], trials=3)
    uri = f"sqlite:///{tmp_path / 'store' / 'mlflow.db'}"
    broken_cell = next(c for c in grid.cells if c.approach == "MAP-LIS" and c.index == 1)
    broken = trial_dir(work_root(grid.config, uri), grid, broken_cell)
    broken.parent.mkdir(parents=True)
    broken.write_text("a file where the trial folder should be")
    result = launch(grid, progress=False)
    assert [o.trial_key for o in result.failed] == [broken_cell.key]

    report = build_report(result.tracking_uri, grid.grid_id, tmp_path / "report")

    trials = pd.read_csv(report.out_dir / "trials.csv").set_index("trial_key")
    assert sorted(trials.index) == sorted(c.key for c in grid.cells)
    assert trials.loc[broken_cell.key, "status"] == "FAILED"
    client = MlflowClient(result.tracking_uri)
    for key, row in trials[trials.status == "FINISHED"].iterrows():
        history = client.get_metric_history(row.run_id, "best_loss")
        assert row.best_loss == pytest.approx(min(m.value for m in history)), key
    summary = report.summary.set_index("approach")
    assert summary.loc["MAP-LIS", ["n_finished", "n_failed"]].tolist() == [2, 1]
    assert summary.loc["EA", "n_finished"] == 3
    assert len(report.tests) == 1
    names = {p.name for p in report.files}
    assert {"best_loss.png", "repertoire_maps.pdf", "paths_Fp.png", "convergence.png"} <= names
    logged = {a.path for a in client.list_artifacts(result.parent_run_id, "report")}
    assert "report/report.html" in logged
