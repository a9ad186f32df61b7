"""Benchmark: predicting a whole repertoire with the learned walk model, against walking it.

Run: `.venv/bin/python benchmarks/walkmodel_speed.py [--cells 10000] [--sample 24]`.

A repertoire of `--cells` random genomes that pass the 2-D checks (paper mode) is predicted
on one core by a walk model fitted on walks of the same kind (its size is what a trained
model has; its weights do not change its speed): `sim.robot.walk_features` (each cell's LEGO
build found by `sim.robot.builds`, the 2-D kernel's simulation of it, its checks and tripod gait)
plus the ensemble's forward pass, process CPU time, best of 3. In the same run: the builds
alone, against `sim.robot.lego.closest_build` (every rounding simulated, the closest kept)
on `--sample` of the cells; and the walk map's cost: `--sample` cells built and walked 10 s
on both floors (`sim.robot.walk_map.walk_cells`), per cell, times `--cells`.
Goal: <= 2 s for 10,000 cells, build features included.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=10_000)
    parser.add_argument("--sample", type=int, default=24)
    args = parser.parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core
    import numba

    numba.set_num_threads(1)
    from linkevo.algorithms.walk_model import WalkData, WalkModel
    from linkevo.sim import decode, simulate
    from linkevo.sim.linkage.physical import physical_checks
    from linkevo.sim.robot.builds import lego_builds
    from linkevo.sim.robot.lego import QuantiseError, closest_build
    from linkevo.sim.robot.walk_features import FEATURE_NAMES, walk_features
    from linkevo.sim.robot.walk_map import CellBatch, walk_cells

    rng = np.random.default_rng(0)
    kept = []
    while sum(len(k) for k in kept) < args.cells:
        genomes = rng.random((20_000, 56))
        batch = decode(genomes, "paper")
        kept.append(genomes[physical_checks(batch, simulate(batch)).buildable])
    genomes = np.concatenate(kept)[: args.cells]
    features = walk_features(genomes)
    fake = WalkData(features[:512], rng.normal(50, 20, (512, 2)), rng.integers(0, 2, (512, 2)))
    model = WalkModel(len(FEATURE_NAMES)).fit(fake, seed=0)

    def best_of_3(work) -> float:
        times = []
        for _ in range(3):
            start = time.process_time()
            work()
            times.append(time.process_time() - start)
        return min(times)

    predict_s = best_of_3(lambda: model.predict(walk_features(genomes)))
    features_s = best_of_3(lambda: walk_features(genomes))
    builds_s = best_of_3(lambda: lego_builds(decode(genomes, "paper")))

    start = time.process_time()
    for genome in genomes[: args.sample]:
        with contextlib.suppress(QuantiseError):
            closest_build(genome, "paper")
    plain_per_cell = (time.process_time() - start) / args.sample

    sample = genomes[: args.sample]
    start = time.process_time()
    walk_cells(CellBatch(np.arange(len(sample)), sample, "paper", ("flat", "carpet")))
    per_cell = (time.process_time() - start) / len(sample)
    walk_s = per_cell * args.cells
    print(f"{args.cells} buildable cells (paper mode), one core:")
    print(f"  walk model: {predict_s:.2f} s (features {features_s:.2f} s; goal <= 2 s)")
    print(
        f"  LEGO builds: {builds_s:.2f} s ({builds_s / args.cells * 1e3:.3f} ms a cell); "
        f"the exhaustive search {plain_per_cell * 1e3:.1f} ms a cell ({args.sample} cells): "
        f"{plain_per_cell * args.cells / builds_s:,.0f}x"
    )
    print(
        f"  walk map: {per_cell:.3f} s per cell ({args.sample} built and walked 10 s on both "
        f"floors) = {walk_s / 60:.1f} min for every cell"
    )
    print(f"  prediction is {walk_s / predict_s:,.0f}x faster than walking")


if __name__ == "__main__":
    main()
