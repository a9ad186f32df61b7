"""Benchmarks the driver's limits: trials/s and MLflow writes/s of a grid of tiny trials, on
the embedded sqlite store and on an MLflow server backed by PostgreSQL.

Run from the repository root (PostgreSQL's server programs must be installed):

    .venv/bin/python benchmarks/driver_limits.py [--trials 240] [--clients 8]

Prints, for each store:
1. the grid: `linkevo grid` on a local Ray instance (all CPUs) with `--trials` one-iteration
   trials (EA and RANDOM x Fp and Fsl, 50 evaluations, 12 crank angles): trials/s sustained
   over the fan-out (first trial start to last trial end, read from the store), database
   rows written/s over the same span (runs, tags, params, metric points), the wall time,
   and the time to read all the grid's trial runs back (what a progress poll over the
   whole grid would cost);
2. where one trial's time goes: the same trial body (`workers.trial_task.run_trial_job`)
   run in this process with every `MlflowClient` call timed, split by call;
3. the store's write capacity: `--clients` threads creating, logging (one batch of 10
   metrics, 10 params, 10 tags) and ending runs as fast as they can for 15 s: runs/s.

The sqlite store is a fresh file; the server is `linkevo cluster up`'s (one Ray worker node
of 1 CPU beside it, idle). The plain reference of section 3 is one client.
"""

from __future__ import annotations

import argparse
import collections
import functools
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import ray
from mlflow.entities import Metric, Param, RunTag
from mlflow.tracking import MlflowClient

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from linkevo.orchestrator import config  # noqa: E402
from linkevo.orchestrator.driver import trial_specs  # noqa: E402
from linkevo.orchestrator.grid import Grid  # noqa: E402
from linkevo.orchestrator.local_cluster import ClusterSettings, down, up  # noqa: E402
from linkevo.workers.store.run_layout import trial_runs  # noqa: E402
from linkevo.workers.store.tracking import ensure_experiment  # noqa: E402
from linkevo.workers.trial_task import TrialJob, run_trial_job  # noqa: E402

TINY = {
    "approaches": ["EA", "RANDOM"],
    "fitnesses": ["Fp", "Fsl"],
    "evaluations": 50,
    "batch_size": 50,
    "n_angles": 12,
    "checkpoint_every": 1,
    "evaluators_per_trial": 0,
}
TABLES = ("runs", "tags", "params", "metrics")
"""The database tables a grid writes rows into (a metric point is one row of `metrics`)."""


def grid_config(work: Path, trials_total: int) -> Path:
    """Writes the tiny grid with `trials_total` trials (rounded to the 4 cells) as TOML."""
    cells = len(TINY["approaches"]) * len(TINY["fitnesses"])
    cfg = config.from_dict({**TINY, "trials": max(1, trials_total // cells)})
    path = work / "tiny.toml"
    path.write_text(config.to_toml(cfg))
    return path


def row_counts(uri: str) -> dict[str, int]:
    """Returns the row count of each table in `TABLES` of the store behind `uri`."""
    if uri.startswith("sqlite:///"):
        with sqlite3.connect(uri.removeprefix("sqlite:///")) as db:
            return {t: db.execute(f"select count(*) from {t}").fetchone()[0] for t in TABLES}
    import psycopg2

    with psycopg2.connect(uri.replace("postgresql+psycopg2", "postgresql")) as db:
        cursor = db.cursor()
        counts = {}
        for table in TABLES:
            cursor.execute(f"select count(*) from {table}")
            counts[table] = cursor.fetchone()[0]
        return counts


def run_grid(cfg: Path, uri: str, db_uri: str, work: Path) -> None:
    """Section 1: the grid through the real driver."""
    grid = Grid.from_config(config.load(cfg))
    command = [sys.executable, "-m", "linkevo.orchestrator", "grid", str(cfg)]
    command += ["--tracking-uri", uri, "--no-progress", "--set", f'work_dir="{work / "trials"}"']
    before = row_counts(db_uri) if not uri.startswith("sqlite") else dict.fromkeys(TABLES, 0)
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, cwd=work, check=False)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        print(done.stdout[-1500:], done.stderr[-1500:])
    client = MlflowClient(uri)
    experiment = client.get_experiment_by_name(grid.config.experiment)
    runs = trial_runs(client, experiment.experiment_id, grid.grid_id)
    span = (max(r.info.end_time for r in runs) - min(r.info.start_time for r in runs)) / 1e3
    after = row_counts(db_uri)
    rows = {t: after[t] - before[t] for t in TABLES}
    start = time.perf_counter()
    trial_runs(client, experiment.experiment_id, grid.grid_id)
    read_all = time.perf_counter() - start
    print(
        f"grid of {len(runs)} trials: {wall:.1f} s wall (exit {done.returncode}), "
        f"fan-out {span:.1f} s"
    )
    split = ", ".join(f"{t} {n / len(runs):.0f}" for t, n in rows.items())
    print(
        f"  sustained: {len(runs) / span:.2f} trials/s, "
        f"{sum(rows.values()) / span:,.0f} rows written/s ({split} per trial)"
    )
    print(
        f"  reading the grid's {len(runs)} trial runs back: {read_all * 1e3:.0f} ms "
        f"({read_all / len(runs) * 1e6:.0f} us per run)"
    )


def time_client_calls() -> tuple[dict[str, list[float]], callable]:
    """Wraps every public `MlflowClient` method with a timer; returns (timings, undo)."""
    timings: dict[str, list[float]] = collections.defaultdict(list)
    originals = {}
    for name in dir(MlflowClient):
        method = getattr(MlflowClient, name)
        if name.startswith("_") or not callable(method) or isinstance(method, type):
            continue
        originals[name] = method

        def timed(*args, _method=method, _name=name, **kwargs):
            start = time.perf_counter()
            try:
                return _method(*args, **kwargs)
            finally:
                timings[_name].append(time.perf_counter() - start)

        setattr(MlflowClient, name, functools.wraps(method)(timed))

    def undo() -> None:
        for name, method in originals.items():
            setattr(MlflowClient, name, method)

    return timings, undo


def trial_breakdown(cfg: Path, uri: str, work: Path, n: int = 20) -> None:
    """Section 2: where one trial's time goes, by MLflow call, over `n` trials in process."""
    grid = Grid.from_config(config.load(cfg))
    experiment_id = ensure_experiment(uri, "driver-limits")
    parent = MlflowClient(uri).create_run(experiment_id).info.run_id
    specs = list(trial_specs(grid).items())[:n]
    timings, undo = time_client_calls()
    start = time.perf_counter()
    try:
        for i, (key, spec) in enumerate(specs):
            job = TrialJob(
                tracking_uri=uri,
                experiment_id=experiment_id,
                parent_run_id=parent,
                grid_id=f"bench-{time.time_ns()}",
                trial_key=key,
                trial_index=i,
                spec=spec,
                out_dir=str(work / "in-process" / str(i)),
                evaluators=0,
                cpus_per_evaluator=1.0,
            )
            run_trial_job(job)
    finally:
        undo()
    per_trial = (time.perf_counter() - start) / len(specs)
    # A call made inside another timed call (get_run inside download_artifacts) is counted
    # in both; the split lists the calls a trial makes itself.
    calls = sorted(timings.items(), key=lambda kv: -sum(kv[1]))
    tracked = sum(sum(v) for _, v in calls) / len(specs)
    print(
        f"one trial in process: {per_trial * 1e3:.0f} ms, of which MLflow calls "
        f"{tracked * 1e3:.0f} ms ({tracked / per_trial:.0%})"
    )
    for name, values in calls[:8]:
        print(
            f"  {name:<18} {len(values) / len(specs):5.1f} calls  "
            f"{sum(values) / len(specs) * 1e3:7.1f} ms per trial  "
            f"({sum(values) / len(values) * 1e3:.1f} ms each)"
        )


def write_capacity(uri: str, clients: int, seconds: float = 15.0) -> float:
    """Section 3: runs/s that `clients` threads sustain creating, logging and ending runs."""
    experiment_id = ensure_experiment(uri, "driver-limits")
    done = [0] * clients
    stop = time.monotonic() + seconds

    def work(i: int) -> None:
        client = MlflowClient(uri)
        stamp = int(time.time() * 1000)
        while time.monotonic() < stop:
            run_id = client.create_run(experiment_id).info.run_id
            client.log_batch(
                run_id,
                metrics=[Metric(f"m{k}", float(k), stamp, 0) for k in range(10)],
                params=[Param(f"p{k}", str(k)) for k in range(10)],
                tags=[RunTag(f"t{k}", str(k)) for k in range(10)],
            )
            client.set_terminated(run_id, "FINISHED")
            done[i] += 1

    threads = [threading.Thread(target=work, args=(i,)) for i in range(clients)]
    start = time.monotonic()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return sum(done) / (time.monotonic() - start)


def bench_store(name: str, uri: str, db_uri: str, args: argparse.Namespace, work: Path) -> None:
    """Runs the three sections on one store."""
    print(f"\n## {name}: {uri}")
    cfg = grid_config(work, args.trials)
    run_grid(cfg, uri, db_uri, work)
    trial_breakdown(cfg, uri, work)
    one = write_capacity(uri, 1)
    many = write_capacity(uri, args.clients)
    print(
        f"write capacity: {one:.0f} runs/s with 1 client, {many:.0f} runs/s with "
        f"{args.clients} clients ({many / one:.1f}x)"
    )


def main() -> None:
    """Runs the benchmark on both stores."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=240)
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument(
        "--stores", nargs="+", choices=["sqlite", "server"], default=["sqlite", "server"]
    )
    args = parser.parse_args()
    ray.init(address="local", num_cpus=1, include_dashboard=False)  # run_trial_job tags its node
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        if "sqlite" in args.stores:
            (work / "sqlite").mkdir()
            sqlite = f"sqlite:///{work / 'sqlite' / 'mlflow.db'}"
            ensure_experiment(sqlite)
            bench_store("embedded sqlite", sqlite, sqlite, args, work / "sqlite")
        if "server" in args.stores:
            state = up(ClusterSettings(dir=work / "cluster", workers=1))
            try:
                (work / "server").mkdir()
                bench_store(
                    "MLflow server on PostgreSQL",
                    state.tracking_uri,
                    state.database_uri,
                    args,
                    work / "server",
                )
            finally:
                down(work / "cluster")
    ray.shutdown()


if __name__ == "__main__":
    main()
