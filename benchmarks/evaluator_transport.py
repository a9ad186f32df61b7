"""Benchmarks evaluator actors: one study-budget trial on a `linkevo cluster up` cluster with
two worker nodes, evaluated in its own task or through two evaluator actors.

Run from the repository root (needs PostgreSQL's server programs, as `cluster up` does):

    .venv/bin/python benchmarks/evaluator_transport.py [--evaluations 726750] [--repeats 3]

The trial (MAP-LIS, F_p, batches of 5,000, no tracking) runs as a Ray task on the first
worker node, in these set-ups, each the best of `--repeats` runs, taking turns:
- **own task, 1 / 2 threads**: `LocalEvaluator`, numba threads in the task (the default,
  `evaluators_per_trial = 0`);
- **2 actors, its node**: both actors on the trial's node;
- **2 actors, both nodes**: one actor on each worker node.
Batches and results go through Ray's object store.
Every set-up must give the same best loss (printed). The ratio column is each set-up's
time over the own-task time with 2 threads.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import ray
from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from linkevo.orchestrator.local_cluster import ClusterSettings, down, up
from linkevo.sim.study import STUDY_EVALUATIONS
from linkevo.workers.trial_spec import TrialSpec

SETUPS: dict[str, tuple[int, str]] = {
    "own task, 1 thread": (1, ""),
    "own task, 2 threads": (2, ""),
    "2 actors, its node": (0, "same"),
    "2 actors, both nodes": (0, "spread"),
}
"""name -> (numba threads in the task, or 0 for actors; where the actors go)."""


def run_setup(spec: TrialSpec, threads: int, place: str, nodes: list[str]):
    """Runs the trial once as a task on nodes[0]; returns (seconds, best loss)."""

    @ray.remote(num_cpus=0)
    def trial() -> tuple[float, float]:
        import numba

        from linkevo.workers.evaluators import LocalEvaluator
        from linkevo.workers.ray_evaluator import ActorPoolEvaluator, EvaluatorWorker
        from linkevo.workers.recorders import NullRecorder
        from linkevo.workers.trial import run_trial

        if threads:
            numba.set_num_threads(threads)
            evaluator = LocalEvaluator(spec.fitness, spec.mode, spec.target, spec.n_angles)
        else:
            homes = [nodes[0], nodes[0]] if place == "same" else nodes[:2]
            actors = [
                ray.remote(EvaluatorWorker)
                .options(num_cpus=1, scheduling_strategy=NodeAffinitySchedulingStrategy(n, False))
                .remote(
                    fitness=spec.fitness,
                    mode=spec.mode,
                    target=spec.target,
                    n_angles=spec.n_angles,
                    threads=1,
                )
                for n in homes
            ]
            evaluator = ActorPoolEvaluator(actors)
            ray.get([a.evaluate.remote(_warm_genomes()) for a in actors])  # started, compiled
        with tempfile.TemporaryDirectory() as out:
            start = time.perf_counter()
            result = run_trial(spec, evaluator, NullRecorder(), Path(out))
            seconds = time.perf_counter() - start
        if not threads:
            evaluator.close()
        return seconds, float(result.best_loss)

    strategy = NodeAffinitySchedulingStrategy(nodes[0], False)
    return ray.get(trial.options(scheduling_strategy=strategy).remote())


def _warm_genomes():
    import numpy as np

    from linkevo.sim import random_genomes

    return random_genomes(np.random.default_rng(0), 10)


def measure(address: str, nodes: list[str], spec: TrialSpec, repeats: int) -> None:
    """Joins the cluster at `address` and prints the table (run in a process whose
    environment holds the cluster's token settings, which Ray reads when it is imported)."""
    ray.init(address=address)
    best: dict[str, tuple[float, float]] = {}
    for _ in range(repeats):
        for name, (threads, place) in SETUPS.items():
            seconds, loss = run_setup(spec, threads, place, nodes)
            if name not in best or seconds < best[name][0]:
                best[name] = (seconds, loss)
    ray.shutdown()
    base = best["own task, 2 threads"][0]
    print(
        f"MAP-LIS F_p, {spec.evaluations:,} evaluations, batches of {spec.batch_size:,}; "
        f"2 worker nodes x 2 CPUs on {os.cpu_count()} cores; best of {repeats}"
    )
    print(f"{'set-up':<36} {'seconds':>8} {'ratio':>6} {'best loss':>10}")
    for name, (seconds, loss) in best.items():
        print(f"{name:<36} {seconds:8.2f} {seconds / base:6.2f} {loss:10.4f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--evaluations", type=int, default=STUDY_EVALUATIONS)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--join", nargs="+", help=argparse.SUPPRESS)  # ADDRESS NODE NODE
    args = parser.parse_args()
    spec = TrialSpec(approach="MAP-LIS", fitness="Fp", evaluations=args.evaluations, seed=3)
    if args.join:
        measure(args.join[0], args.join[1:], spec, args.repeats)
        return
    with tempfile.TemporaryDirectory() as work:
        state = up(ClusterSettings(dir=Path(work) / "cluster", workers=2, cpus_per_worker=2))
        try:
            command = [
                sys.executable,
                __file__,
                "--evaluations",
                str(args.evaluations),
                "--repeats",
                str(args.repeats),
                "--join",
                state.address,
                *(n.node_id for n in state.workers),
            ]
            subprocess.run(command, env={**os.environ, **state.env}, check=True)
        finally:
            down(Path(work) / "cluster")


if __name__ == "__main__":
    main()
