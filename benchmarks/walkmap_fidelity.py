"""Benchmark: what a coarser physics step would buy a walk map, and what it would cost in
agreement with the Table I walk, in one run.

Run: `.venv/bin/python benchmarks/walkmap_fidelity.py --run-id RUN_ID [--tracking-uri URI]
[--cells 24] [--steps 0.004 0.005]`: RUN_ID is a repertoire trial (the benchmark's: MAP-LIS's
first robot's trial of the paper-mode study grid, `docs/results.md`). The same `--cells`
buildable cells (every k-th by loss) are walked once per floor (a walk-map walk, 10 s) at the
lean model's step and at each coarser `--steps`, on one core. Per floor and step it prints the
time per walk and its ratio to the lean step's, and the agreement with the lean step's walks:
Spearman's rank correlation of the distances, the median and largest difference, and the
share of cells whose break verdict agrees. A "confirmed" line re-walks at the lean step every
cell that breaks at the coarse one (a break is then always the Table I physics' verdict) and
counts that time too.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from mlflow.tracking import MlflowClient
from scipy.stats import spearmanr

from linkevo.orchestrator.explore import trial_run
from linkevo.orchestrator.walkmap import Selection
from linkevo.sim.leg import leg_from_genome
from linkevo.sim.robot import FLOORS
from linkevo.sim.walk import WalkSettings, walk
from linkevo.sim.walk_map import WALK_SECONDS
from linkevo.workers.store.linkages import repertoire


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--tracking-uri", default="sqlite:///runs/mlflow.db")
    parser.add_argument("--cells", type=int, default=24)
    parser.add_argument("--steps", type=float, nargs="+", default=[0.004, 0.005])
    args = parser.parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    client = MlflowClient(tracking_uri=args.tracking_uri)
    trial = trial_run(client, args.run_id)
    with tempfile.TemporaryDirectory() as tmp:
        table = repertoire(client, args.run_id, Path(tmp))
    buildable = Selection("buildable").choose(table, trial.mode)
    chosen = buildable.iloc[:: max(1, len(buildable) // args.cells)].head(args.cells)
    lean = WalkSettings(seconds=WALK_SECONDS).step
    steps = [lean, *args.steps]
    print(f"{trial.trial_key}: {len(chosen)} of {len(buildable)} buildable cells, steps (ms): "
          f"{', '.join(f'{s * 1000:g}' for s in steps)}")  # fmt: skip
    # distance (cm), breaks, seconds per (step, floor): lists over cells
    walks: dict[tuple[float, str], list[tuple[float, bool, float]]] = {}
    for genome in chosen["genome"]:
        leg = leg_from_genome(np.asarray(genome, dtype=np.float64), trial.mode)
        for floor in FLOORS:
            for step in steps:
                start = time.perf_counter()
                w = walk(leg, FLOORS[floor], settings=WalkSettings(WALK_SECONDS, timestep=step))
                seconds = time.perf_counter() - start
                walks.setdefault((step, floor), []).append((w.distance_m * 100, w.breaks, seconds))
    for floor in FLOORS:
        reference = np.array(walks[(lean, floor)])
        print(f"{floor}: {lean * 1000:g} ms, {reference[:, 2].mean():.3f} s a walk")
        for step in args.steps:
            coarse = np.array(walks[(step, floor)])
            broken = coarse[:, 1].astype(bool)
            confirmed = np.where(broken[:, None], reference, coarse)
            for name, got, seconds in (
                ("as walked", coarse, coarse[:, 2].mean()),
                ("confirmed", confirmed, (coarse[:, 2] + broken * reference[:, 2]).mean()),
            ):
                diff = np.abs(got[:, 0] - reference[:, 0])
                print(
                    f"  {step * 1000:g} ms, {name}: {seconds:.3f} s a walk "
                    f"({reference[:, 2].mean() / seconds:.2f}x); Spearman "
                    f"{spearmanr(reference[:, 0], got[:, 0])[0]:.3f}, difference median "
                    f"{np.median(diff):.1f} cm, largest {diff.max():.1f} cm; break verdicts "
                    f"agree for {np.mean(got[:, 1] == reference[:, 1]):.0%}"
                )


if __name__ == "__main__":
    main()
