"""Benchmark: `linkevo report` on a 120-trial grid, against a naive per-run loading path.

Writes a real MLflow store (sqlite + file artefacts) holding a study-sized grid in the
driver's layout (6 approaches x 2 fitnesses x 10 trials, 145 iterations, archives of
10,000 rows with genomes and foot paths), then times:

- batched (ours): `orchestrator.report.load_grid` (one paged run search, `metrics.csv`
  and column-selected parquet read in place, a thread pool for anything remote), and the
  whole `build_report` (load + statistics + figures + HTML + logging to the parent run);
- naive reference: per run, `MlflowClient.get_metric_history` for every metric, then
  `mlflow.artifacts.download_artifacts` of the archive and a full `pandas.read_parquet`,
  one run after another.

Run: .venv/bin/python benchmarks/report_speed.py [--store DIR] [--rows 10000]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parent.parent
os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")
sys.path.insert(0, str(REPO))  # for tests.helpers

from linkevo.orchestrator.report import build_report, load_grid  # noqa: E402
from tests.helpers.report import GridSpec, store_uri, write_grid  # noqa: E402

APPROACHES = ("EA", "NSGA-II", "MAP-WH", "MAP-LIS", "MAP-ST", "MAP-AU")
METRICS = ("evaluations", "best_loss", "mean_loss", "coverage", "qd_score", "hypervolume")


def naive_load(uri: str, grid_id: str, dst: Path) -> int:
    """Loads every trial the plain way; returns the number of metric points read."""
    import mlflow.artifacts
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri=uri)
    experiment = client.get_experiment_by_name("linkevo").experiment_id
    runs = client.search_runs(
        [experiment], f"tags.grid_id = '{grid_id}' and tags.`linkevo.kind` = 'trial'"
    )
    points = 0
    for run in runs:
        for name in METRICS:
            if name in run.data.metrics:
                points += len(client.get_metric_history(run.info.run_id, name))
        names = [a.path for a in client.list_artifacts(run.info.run_id)]
        archive = next(n for n in names if n.endswith(".parquet"))
        local = mlflow.artifacts.download_artifacts(
            run_id=run.info.run_id,
            artifact_path=archive,
            dst_path=str(dst / run.info.run_id),
            tracking_uri=uri,
        )
        pd.read_parquet(local)
    return points


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--store", type=Path, default=None, help="reuse or create a store here")
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--rows", type=int, default=10_000, help="rows per archive")
    parser.add_argument("--iterations", type=int, default=145)
    args = parser.parse_args()
    folder = args.store or Path(tempfile.mkdtemp(prefix="report-bench-"))
    spec = GridSpec(
        grid_id="bench120",
        approaches=APPROACHES,
        trials=args.trials,
        iterations=args.iterations,
        batch_size=5000,
        archive_rows=args.rows,
    )
    uri = store_uri(folder)
    if not (folder / "mlflow.db").is_file():
        start = time.perf_counter()
        write_grid(folder, spec)
        print(f"wrote the store in {time.perf_counter() - start:.1f} s: {folder}")
    n = len(APPROACHES) * 2 * args.trials
    from mlflow.tracking import MlflowClient

    # Pay the imports and the store's first connection before timing either path.
    MlflowClient(tracking_uri=uri).search_experiments()
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        grid = load_grid(uri, spec.grid_id, Path(tmp))
        batched = time.perf_counter() - start
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        points = naive_load(uri, spec.grid_id, Path(tmp))
        naive = time.perf_counter() - start
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        result = build_report(uri, spec.grid_id, Path(tmp) / "out")
        full = time.perf_counter() - start
    print(f"trials: {n} ({len(grid.finished())} finished), archive rows: {args.rows}")
    print(f"history rows loaded: {len(grid.history)} (naive read {points} metric points)")
    print(f"load, batched (ours):          {batched:7.2f} s")
    print(f"load, naive per-run reference: {naive:7.2f} s")
    print(f"ratio naive / batched:         {naive / batched:7.1f} x")
    print(f"full report (load + stats + {len(result.files)} files + MLflow logging): {full:.2f} s")


if __name__ == "__main__":
    main()
