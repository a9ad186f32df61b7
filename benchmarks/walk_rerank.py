"""Benchmark: what walking as a re-ranking step costs a trial, and what it finds.

Run: `.venv/bin/python benchmarks/walk_rerank.py [--walks 20] [--approach MAP-LIS]`, pinned
to one core: one F_p trial at the study's budget (725,000 evaluations, paper mode, seed 0)
without re-ranking and the same trial with `walk_rerank = --walks`, in one run. Prints both
wall times, their ratio, the best walker's distance and the distance of the trial's
best-loss linkage walked the same way (what F_p alone would have handed a builder).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import pandas as pd

from linkevo.sim.linkage.linkage_doc import from_document
from linkevo.sim.robot.walk_map import CellBatch, walk_cells
from linkevo.workers.evaluators import LocalEvaluator
from linkevo.workers.recorders import NullRecorder
from linkevo.workers.trial import run_trial
from linkevo.workers.trial_spec import TrialSpec

EVALUATIONS = 725_000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--walks", type=int, default=20)
    parser.add_argument("--approach", default="MAP-LIS")
    args = parser.parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    figures = {}
    for walks in (0, args.walks):
        spec = TrialSpec(args.approach, "Fp", EVALUATIONS, 5000, seed=0, walk_rerank=walks)
        evaluator = LocalEvaluator(spec.eval_fitness, spec.mode, spec.target, spec.n_angles)
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            result = run_trial(spec, evaluator, NullRecorder(), Path(tmp))
            seconds = time.perf_counter() - start
            figures[f"trial_s_walk_rerank_{walks}"] = round(seconds, 1)
            if walks:
                ranked = pd.read_parquet(Path(tmp) / "walk_rerank.parquet")
                figures["best_walker_cm"] = round(result.metrics["best_walk_cm"], 1)
                figures["breaking"] = int(ranked["breaks"].sum())
            else:
                best = json.loads((Path(tmp) / "best_linkage.json").read_text())
                genome, mode = from_document(best)
                row = walk_cells(CellBatch([0], genome[None], mode, ("flat",)))[0]
                figures["best_loss_linkage_cm"] = round(row["mean_distance_cm"], 1)
                figures["best_loss_linkage_breaks"] = bool(row["breaks"])
    figures["cost_ratio"] = round(
        figures[f"trial_s_walk_rerank_{args.walks}"] / figures["trial_s_walk_rerank_0"], 2
    )
    print(
        f"{args.approach} F_p, {EVALUATIONS:,} evaluations, one core: "
        f"{figures['trial_s_walk_rerank_0']} s plain, "
        f"{figures[f'trial_s_walk_rerank_{args.walks}']} s with {args.walks} walks "
        f"({figures['cost_ratio']}x); best walker {figures['best_walker_cm']} cm on flat "
        f"against {figures['best_loss_linkage_cm']} cm for the best-loss linkage"
    )
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
