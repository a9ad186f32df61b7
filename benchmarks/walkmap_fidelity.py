"""Benchmark: the walk-map walk against the Table I protocol it stands for, in one run.

Run: `.venv/bin/python benchmarks/walkmap_fidelity.py --run-id RUN_ID [--tracking-uri URI]
[--cells 24]`: RUN_ID is a repertoire trial (the benchmark's: MAP-LIS's first robot's trial
of the paper-mode study grid, `docs/results.md`). The same `--cells` buildable cells (every
k-th by loss) are walked on each floor, on one core, four ways: the Table I protocol
(`sim.robot.walking.field_trials`: five 10-s walks from hand-placed starts at the lean model's 2-ms
step, their mean), one Table I walk from the unperturbed start, the walk-map walk
(`sim.robot.walk_map.walk_map_settings`: one walk at 4 ms with the sparse Jacobian), and the
walking fitness's walk (`sim.robot.walk_fitness.search_walk_settings`: the walk-map walk for 5 s,
stopped once the robot has broken, its distance doubled to 10 s). Per floor and way it
prints the time per cell and its ratio to the protocol's, and the agreement with the
protocol: Spearman's rank correlation of the distances (over every cell, and over the cells
that do not break in the protocol), the median and largest difference, and the share of
cells whose break verdict agrees.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from linkevo.orchestrator.repertoire_walks import Selection
from linkevo.sim.robot.hexapod import FLOORS, WALK_SECONDS
from linkevo.sim.robot.leg import leg_from_genome
from linkevo.sim.robot.walk_fitness import search_walk_settings
from linkevo.sim.robot.walk_map import walk_map_settings
from linkevo.sim.robot.walking import WalkSettings, field_trials, walk
from linkevo.workers.store.runs import RunStore

WAYS = ("Table I protocol (5 walks)", "one Table I walk", "walk-map walk", "F_w walk")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--tracking-uri", default="sqlite:///runs/mlflow.db")
    parser.add_argument("--cells", type=int, default=24)
    args = parser.parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    store = RunStore(args.tracking_uri)
    trial = store.repertoire_trial(args.run_id)
    with tempfile.TemporaryDirectory() as tmp:
        table = store.repertoire(args.run_id, Path(tmp))
    buildable = Selection("buildable").choose(table, trial.mode)
    chosen = buildable.iloc[:: max(1, len(buildable) // args.cells)].head(args.cells)
    print(f"{trial.trial_key}: {len(chosen)} of {len(buildable)} buildable cells")
    table_one = WalkSettings(seconds=WALK_SECONDS)
    # per (way, floor), over cells: distance (cm), breaks, seconds
    got: dict[tuple[str, str], list[tuple[float, bool, float]]] = {}
    for genome in chosen["genome"]:
        leg = leg_from_genome(np.asarray(genome, dtype=np.float64), trial.mode)
        for floor in FLOORS:
            start = time.perf_counter()
            walks = field_trials(leg, FLOORS[floor], settings=table_one)
            mean = float(np.mean([w.distance_m * 100 for w in walks]))
            got.setdefault((WAYS[0], floor), []).append(
                (mean, any(w.breaks for w in walks), time.perf_counter() - start)
            )
            ways = (table_one, walk_map_settings(), search_walk_settings())
            for way, settings in zip(WAYS[1:], ways, strict=True):
                start = time.perf_counter()
                w = walk(leg, FLOORS[floor], settings=settings)
                seconds = time.perf_counter() - start
                per_10_s = w.distance_m * 100 * WALK_SECONDS / settings.seconds
                got.setdefault((way, floor), []).append((per_10_s, w.breaks, seconds))
    for floor in FLOORS:
        protocol = np.array(got[(WAYS[0], floor)])
        sound = ~protocol[:, 1].astype(bool)
        print(f"{floor}: {WAYS[0]} {protocol[:, 2].mean():.3f} s a cell")
        for way in WAYS[1:]:
            one = np.array(got[(way, floor)])
            diff = np.abs(one[:, 0] - protocol[:, 0])
            print(
                f"  {way}: {one[:, 2].mean():.3f} s a cell "
                f"({protocol[:, 2].mean() / one[:, 2].mean():.1f}x); Spearman "
                f"{spearmanr(protocol[:, 0], one[:, 0])[0]:.3f} (cells that do not break: "
                f"{spearmanr(protocol[sound, 0], one[sound, 0])[0]:.3f}, {sound.sum()}); "
                f"difference median {np.median(diff):.1f} cm, largest {diff.max():.1f} cm; "
                f"break verdicts agree for {np.mean(one[:, 1] == protocol[:, 1]):.0%}"
            )


if __name__ == "__main__":
    main()
