"""Benchmark: decode + simulate + F_p throughput of the kernel against the plain reference.

Run: `.venv/bin/python benchmarks/sim_throughput.py` (options: --sizes, --repeats,
--reference-size). Prints one line per measurement and, last, one JSON object with
`evals_per_s` (the best 2-thread kernel figure) and `ratio_vs_reference` (kernel per core
over reference per core).

The kernel is timed two ways: writing into result arrays that are reused from call to
call (`sim.evaluate(..., out=...)`, what `LocalEvaluator` and the evaluator actors do) and
into fresh arrays on every call, whose first-touch page faults (about 0.3 µs per genome
here) are the allocator's cost, not the kernel's. The four set-ups (1 and 2 threads,
reused or fresh arrays) take turns call by call for `--repeats` rounds after a warm-up
round, so drifting load on a shared machine reaches all of them alike; each keeps its
best call.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numba
import numpy as np

from sim.evaluate import evaluate
from sim.evaluation import Evaluation
from sim.genome import random_genomes
from sim.reference import evaluate_reference


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[5_000, 50_000])
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--reference-size", type=int, default=1_000)
    parser.add_argument("--mode", default="paper", choices=["paper", "legacy"])
    args = parser.parse_args()

    rng = np.random.default_rng(2024)
    machine = platform.processor() or platform.machine()
    print(f"# {machine}, {os.cpu_count()} CPUs, numba {numba.__version__}")
    evaluate(random_genomes(rng, 16), "Fp", args.mode)  # compile or load the cached kernel

    results: dict[str, float] = {}
    for n in args.sizes:
        genomes = random_genomes(rng, n)
        out = Evaluation.empty(n, 40, 1)
        setups = {
            (name, threads): (threads, kwargs)
            for threads in (1, 2)
            for name, kwargs in (("kernel", {"out": out}), ("fresh", {}))
        }
        best = dict.fromkeys(setups, np.inf)
        for round_ in range(args.repeats + 1):  # round 0 warms up
            for key, (threads, kwargs) in setups.items():
                numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
                start = time.perf_counter()
                evaluate(genomes, "Fp", args.mode, **kwargs)
                if round_:
                    best[key] = min(best[key], time.perf_counter() - start)
        for (name, threads), seconds in best.items():
            rate = n / seconds
            results[f"{name}_{n}_{threads}t"] = rate
            print(
                f"{name:<9} n={n:>6} threads={threads}: {rate:>12,.0f} evals/s "
                f"({seconds * 1e3:.1f} ms)"
            )

    genomes = random_genomes(rng, args.reference_size)
    evaluate_reference(genomes[:10], "Fp", args.mode)  # warm-up
    start = time.perf_counter()
    evaluate_reference(genomes, "Fp", args.mode)
    seconds = time.perf_counter() - start
    reference = args.reference_size / seconds
    print(f"reference n={args.reference_size:>6} threads=1: {reference:>12,.0f} evals/s")

    best_2t = max(v for k, v in results.items() if k.startswith("kernel") and k.endswith("_2t"))
    best_1t = max(v for k, v in results.items() if k.startswith("kernel") and k.endswith("_1t"))
    ratio = best_1t / reference
    print(f"ratio kernel/reference per core: {ratio:,.0f}x; 2 threads: {best_2t / reference:,.0f}x")
    print(
        json.dumps(
            {
                "evals_per_s": round(best_2t),
                "evals_per_s_1thread": round(best_1t),
                "reference_evals_per_s": round(reference),
                "ratio_vs_reference": round(ratio, 1),
                "mode": args.mode,
                **{k: round(v) for k, v in results.items()},
            }
        )
    )


if __name__ == "__main__":
    main()
