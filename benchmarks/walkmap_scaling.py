"""Benchmark: walk-map walks per second, in process on one core against Ray with 2 workers
on 2 cores, in one run.

Run: `.venv/bin/python benchmarks/walkmap_scaling.py --run-id RUN_ID [--tracking-uri URI]
[--cells 48]`: RUN_ID is a repertoire trial (by default the benchmark's: MAP-LIS's first
robot's trial of the paper-mode study grid, `docs/results.md`). The same `--cells`
buildable cells (spread over the map: every k-th by loss) are walked on both floors by
`orchestrator.walkmap` in each set-up, nothing logged; the full repertoire's time is
extrapolated from the rate and the trial's count of buildable cells. Goal: >= 1.7x from 2
workers, a full repertoire in <= 30 min on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from mlflow.tracking import MlflowClient

from linkevo.orchestrator.explore import trial_run
from linkevo.orchestrator.walkmap import Selection, plan, run_in_process, run_on_ray
from linkevo.workers.store.linkages import repertoire

FLOORS = ("flat", "carpet")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--tracking-uri", default="sqlite:///runs/mlflow.db")
    parser.add_argument("--cells", type=int, default=48)
    args = parser.parse_args()
    client = MlflowClient(tracking_uri=args.tracking_uri)
    trial = trial_run(client, args.run_id)
    with tempfile.TemporaryDirectory() as tmp:
        table = repertoire(client, args.run_id, Path(tmp))
    buildable = Selection("buildable").choose(table, trial.mode)
    step = max(1, len(buildable) // args.cells)
    chosen = buildable.iloc[::step].head(args.cells)
    batches = plan(chosen, trial.mode, FLOORS, None, as_evolved=False, seconds=10.0)
    walks = len(chosen) * len(FLOORS)
    print(
        f"{trial.trial_key} (run {args.run_id}): {len(table)} cells, {len(buildable)} pass the "
        f"physical checks; walking {len(chosen)} of them on {', '.join(FLOORS)} ({walks} walks)"
    )

    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # the in-process run: one core
    list(run_in_process(plan(chosen.head(1), trial.mode, FLOORS, None, as_evolved=False,
                             seconds=1.0)))  # fmt: skip  # compiled kernels, warm caches
    start = time.perf_counter()
    rows = [r for batch in run_in_process(batches) for r in batch]
    inline_s = time.perf_counter() - start
    os.sched_setaffinity(0, set(range(os.cpu_count() or 1)))

    import ray

    ray.init(num_cpus=2, include_dashboard=False, logging_level="WARNING")
    warm = plan(chosen.head(2), trial.mode, FLOORS, None, as_evolved=False, seconds=1.0)
    list(run_on_ray(warm + warm, in_flight=4))  # both workers up and warm before timing
    start = time.perf_counter()
    ray_rows = [r for batch in run_on_ray(batches, in_flight=4) for r in batch]
    ray_s = time.perf_counter() - start
    ray.shutdown()

    same = sorted((r["cell"], r["floor"], r["mean_distance_cm"]) for r in rows) == sorted(
        (r["cell"], r["floor"], r["mean_distance_cm"]) for r in ray_rows
    )
    full = len(buildable) * len(FLOORS)
    figures = {
        "walks": walks,
        "in_process_walks_per_s": round(walks / inline_s, 3),
        "ray_2_workers_walks_per_s": round(walks / ray_s, 3),
        "speed_up": round(inline_s / ray_s, 2),
        "cpu_s_per_walk": round(inline_s / walks, 3),
        "full_repertoire_walks": full,
        "full_repertoire_min_2_cores": round(full / (walks / ray_s) / 60, 1),
        "same_distances": same,
    }
    print(
        f"in process, 1 core: {walks / inline_s:.2f} walks/s ({inline_s / walks:.3f} s a walk); "
        f"Ray, 2 workers: {walks / ray_s:.2f} walks/s; speed-up {inline_s / ray_s:.2f}x; "
        f"full repertoire ({full} walks) on 2 cores: {full / (walks / ray_s) / 60:.1f} min; "
        f"same distances both ways: {same}"
    )
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
