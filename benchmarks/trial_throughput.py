"""Benchmarks whole in-process trials at the study's budget, with the time split by phase.

Run from the repository root:

    .venv/bin/python benchmarks/trial_throughput.py [--evaluations 726750] [--approaches ...]

For each trial (default: MAP-LIS F_p and NSGA2 F_p, 726,750 evaluations in batches of
5,000, paper mode) it runs `workers.trial.run_trial` with the in-process evaluator and no
tracking, and prints the wall time split into evaluate, select (ask: parent selection and
mutation), archive (tell: archive insertion or NSGA-II survivor selection) and other
(metrics, metrics.csv, checkpoints, final files).

Plain references, measured in the same run:
1. selection: DEAP's default path on a small batch (`selNSGA2` with the O(M N^2)
   standard sort on DEAP individuals; for MAP-Elites a per-child Python dict archive),
   against our vectorised `select_nsga2` and the pyribs archive `GridArchive.add` on the
   same data;
2. evaluation: the plain per-linkage `sim.linkage.reference.evaluate_reference` on 100 genomes,
   extrapolated to the trial's budget, against the trial's whole wall time.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from deap import base, creator, tools

from linkevo.algorithms import GridArchive, Individuals, select_nsga2
from linkevo.sim import DESCRIPTOR_SPACES, evaluate, random_genomes
from linkevo.sim.linkage.reference import evaluate_reference
from linkevo.sim.study import STUDY_EVALUATIONS
from linkevo.workers.evaluators import LocalEvaluator
from linkevo.workers.recorders import NullRecorder
from linkevo.workers.trial import run_trial
from linkevo.workers.trial_spec import TrialSpec

BATCH = 5000
SMALL_BATCH = 1000
REFERENCE_GENOMES = 100


def run(approach: str, evaluations: int, seed: int) -> float:
    """Runs one trial, prints its time split, returns its wall time."""
    spec = TrialSpec(
        approach=approach, fitness="Fp", evaluations=evaluations, batch_size=BATCH, seed=seed
    )
    evaluator = LocalEvaluator(spec.eval_fitness, spec.mode, spec.target, spec.n_angles)
    evaluator(random_genomes(np.random.default_rng(0), 10))  # compile outside the timing
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        result = run_trial(spec, evaluator, NullRecorder(), Path(tmp))
        total = time.perf_counter() - start
    t = result.timings
    split = {
        "evaluate": t["evaluate"],
        "select": t["ask"],
        "archive": t["tell"],
        "other": total - t["evaluate"] - t["ask"] - t["tell"],
    }
    print(
        f"{approach} Fp: {result.evaluations} evaluations, {result.iterations} iterations, "
        f"{total:.1f} s ({result.evaluations / total:,.0f} evaluations/s); best loss "
        f"{result.best_loss:.3f}, coverage {result.metrics['coverage']:.4f}"
    )
    print("  split: " + ", ".join(f"{k} {v:.2f} s ({v / total:.0%})" for k, v in split.items()))
    return total


def deap_nsga2_seconds(loss: np.ndarray, k: int) -> float:
    """Returns the seconds of DEAP's default selNSGA2 on DEAP individuals."""
    if not hasattr(creator, "BenchFitness"):
        creator.create("BenchFitness", base.Fitness, weights=(-1.0, -1.0))
        creator.create("BenchIndividual", list, fitness=creator.BenchFitness)
    population = []
    for row in loss:
        ind = creator.BenchIndividual()
        ind.fitness.values = tuple(row)
        population.append(ind)
    start = time.perf_counter()
    tools.selNSGA2(population, k)
    return time.perf_counter() - start


def dict_archive_seconds(loss: np.ndarray, desc: np.ndarray, genomes: np.ndarray) -> float:
    """Returns the seconds of a per-child Python dict archive insertion (published binning)."""
    steps = DESCRIPTOR_SPACES["MAP-LIS"].step
    archive: dict[tuple[int, ...], tuple[float, np.ndarray]] = {}
    start = time.perf_counter()
    for value, point, genome in zip(loss.tolist(), desc.tolist(), genomes, strict=True):
        cell = tuple(
            sum(1 for i in range(1, 100) if v > i * s) for v, s in zip(point, steps, strict=True)
        )
        if cell not in archive or value < archive[cell][0]:
            archive[cell] = (value, genome)
    return time.perf_counter() - start


def selection_reference() -> None:
    """Prints DEAP/plain-Python selection against ours on the same small batch."""
    rng = np.random.default_rng(1)
    genomes = random_genomes(rng, 2 * SMALL_BATCH)
    ev2 = evaluate(genomes, "Fp2")
    plain = deap_nsga2_seconds(ev2.loss, SMALL_BATCH)
    start = time.perf_counter()
    select_nsga2(ev2.loss, SMALL_BATCH)
    ours = time.perf_counter() - start
    print(
        f"NSGA-II selection of {SMALL_BATCH} from {2 * SMALL_BATCH}: DEAP default "
        f"{plain * 1e3:.1f} ms, vectorised {ours * 1e3:.2f} ms, ratio {plain / ours:.0f}x"
    )
    ev = evaluate(genomes, "Fp")
    desc = ev.descriptors["MAP-LIS"]
    plain = dict_archive_seconds(ev.loss, desc, genomes)
    batch = Individuals(
        genome=genomes,
        sigma=np.full((len(genomes), 1), 0.1),
        loss=ev.loss,
        error=ev.error,
        angle_error=ev.angle_error,
        desc=desc,
        foot_x=ev.foot_x,
        foot_y=ev.foot_y,
    )
    GridArchive(space=DESCRIPTOR_SPACES["MAP-LIS"]).add(batch)  # imports pyribs
    archive = GridArchive(space=DESCRIPTOR_SPACES["MAP-LIS"])
    start = time.perf_counter()
    archive.add(batch)
    ours = time.perf_counter() - start
    print(
        f"MAP-Elites insertion of {len(genomes)} children: Python dict archive "
        f"{plain * 1e3:.1f} ms, pyribs {ours * 1e3:.2f} ms, ratio {plain / ours:.0f}x"
    )


def evaluation_reference(evaluations: int, trial_seconds: dict[str, float]) -> None:
    """Prints the plain reference evaluator extrapolated to the budget against each trial."""
    genomes = random_genomes(np.random.default_rng(2), REFERENCE_GENOMES)
    start = time.perf_counter()
    evaluate_reference(genomes, "Fp")
    per_genome = (time.perf_counter() - start) / REFERENCE_GENOMES
    plain = per_genome * evaluations
    print(
        f"reference evaluator: {per_genome * 1e3:.2f} ms per genome -> {plain / 60:.0f} min "
        f"for {evaluations} evaluations (extrapolated from {REFERENCE_GENOMES} genomes)"
    )
    for approach, seconds in trial_seconds.items():
        print(f"  {approach} whole trial vs reference evaluation alone: {plain / seconds:.0f}x")


def main() -> None:
    """Runs the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--evaluations", type=int, default=STUDY_EVALUATIONS)
    parser.add_argument("--approaches", nargs="+", default=["MAP-LIS", "NSGA2"])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    seconds = {a: run(a, args.evaluations, args.seed) for a in args.approaches}
    selection_reference()
    evaluation_reference(args.evaluations, seconds)


if __name__ == "__main__":
    main()
