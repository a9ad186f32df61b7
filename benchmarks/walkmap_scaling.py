"""Benchmark: a repertoire's walk map in process on one core against Ray with 2 workers on
2 cores, in one run; with --full, the whole repertoire on 2 cores.

Run: `.venv/bin/python benchmarks/walkmap_scaling.py --run-id RUN_ID [--tracking-uri URI]
[--cells 96] [--full]`: RUN_ID is a repertoire trial (the benchmark's: MAP-LIS's first
robot's trial of the paper-mode study grid, `docs/results.md`). The sample is `--cells`
cells of the map as `linkevo walkmap --cells all` takes them (every cell, as evolved where
no LEGO build turns), a block of neighbouring cells from the middle of the map so that it
holds the cells that share a LEGO build as the whole map does; it is walked on both floors
by `orchestrator.repertoire_walks.walk_rows` in process on one core, then on Ray with 2 workers,
nothing logged. `--full` then walks every cell of the repertoire on Ray with 2 workers the
same way and prints its time. Goal: >= 1.7x from 2 workers; a full repertoire (about 9,000
cells x 2 floors) in <= 30 min on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from linkevo.orchestrator.repertoire_walks import (
    Selection,
    plan,
    run_in_process,
    run_on_ray,
    walk_rows,
)
from linkevo.sim.robot.hexapod import WALK_SECONDS
from linkevo.workers.store.runs import RunStore

FLOORS = ("flat", "carpet")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--tracking-uri", default="sqlite:///runs/mlflow.db")
    parser.add_argument("--cells", type=int, default=96)
    parser.add_argument("--full", action="store_true")
    args = parser.parse_args()
    store = RunStore(args.tracking_uri)
    trial = store.repertoire_trial(args.run_id)
    with tempfile.TemporaryDirectory() as tmp:
        table = store.repertoire(args.run_id, Path(tmp))
    every = Selection("all").choose(table, trial.mode).sort_values("cell", ignore_index=True)
    middle = max(0, len(every) // 2 - args.cells // 2)
    sample = every.iloc[middle : middle + args.cells]

    def walk(chosen, run) -> tuple[list[dict], float]:
        batches = plan(chosen, trial.mode, FLOORS, None, as_evolved=True, seconds=WALK_SECONDS)
        start = time.perf_counter()
        rows = [r for _, part in walk_rows(run, batches, WALK_SECONDS) for r in part]
        return rows, time.perf_counter() - start

    pairs = len(sample) * len(FLOORS)
    print(
        f"{trial.trial_key} (run {args.run_id}): {len(every)} cells; the sample: cells "
        f"{sample['cell'].min()}-{sample['cell'].max()} ({len(sample)} cells, {pairs} cell-floor "
        "pairs)"
    )
    warm = plan(sample.head(2), trial.mode, FLOORS, None, as_evolved=True, seconds=1.0)
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # the in-process run: one core
    list(walk_rows(run_in_process, warm, 1.0))  # compiled kernels, warm caches
    rows, inline_s = walk(sample, run_in_process)
    os.sched_setaffinity(0, set(range(os.cpu_count() or 1)))

    import ray

    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level="WARNING")

    def on_ray(work, items):
        return run_on_ray(work, items, in_flight=4)

    list(walk_rows(on_ray, warm + warm, 1.0))  # both workers up and warm before timing
    ray_rows, ray_s = walk(sample, on_ray)

    def key(r: dict) -> tuple:
        return r["cell"], r["floor"], r["status"], repr(r["mean_distance_cm"])  # NaN too

    figures = {
        "sample_cells": len(sample),
        "in_process_cells_per_s": round(pairs / inline_s, 3),
        "ray_2_workers_cells_per_s": round(pairs / ray_s, 3),
        "speed_up": round(inline_s / ray_s, 2),
        "core_s_per_cell_floor": round(inline_s / pairs, 3),
        "full_repertoire_pairs": len(every) * len(FLOORS),
        "full_repertoire_min_2_cores_extrapolated": round(
            len(every) * len(FLOORS) * ray_s / pairs / 60, 1
        ),
        "same_rows": sorted(map(key, rows)) == sorted(map(key, ray_rows)),
    }
    print(
        f"in process, 1 core: {pairs / inline_s:.2f} cell-floor pairs/s "
        f"({inline_s / pairs:.3f} core-s each); Ray, 2 workers: {pairs / ray_s:.2f}/s; "
        f"speed-up {inline_s / ray_s:.2f}x; the same rows both ways: {figures['same_rows']}"
    )
    if args.full:
        full_rows, full_s = walk(every, on_ray)
        figures["full_repertoire_min_2_cores"] = round(full_s / 60, 1)
        walked = sum(r["status"] == "walked" and bool(r["leg"]) for r in full_rows)
        print(
            f"the whole repertoire on Ray, 2 workers: {len(full_rows)} cell-floor pairs "
            f"({walked} walked, the rest break without walking or failed) in "
            f"{full_s / 60:.1f} min"
        )
    ray.shutdown()
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
