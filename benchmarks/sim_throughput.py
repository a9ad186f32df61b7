"""Benchmark: decode + simulate + F_p throughput of the kernel against the plain reference.

Run: `.venv/bin/python benchmarks/sim_throughput.py` (options: --sizes, --repeats,
--reference-size, --mode, --slices). Prints one line per measurement and, last, one JSON
object with `evals_per_s` (the best 2-thread kernel figure), `ratio_vs_reference` (kernel
per core over reference per core) and `ratio_matched` (the same, timed in alternating
slices).

The kernel is timed two ways: writing into result arrays that are reused from call to
call (`sim.evaluate(..., out=...)`, what `LocalEvaluator` and the evaluator actors do) and
into fresh arrays on every call, whose first-touch page faults (about 0.3 µs per genome
here) are the allocator's cost, not the kernel's. The four set-ups (1 and 2 threads,
reused or fresh arrays) take turns call by call for `--repeats` rounds after a warm-up
round, so drifting load on a shared machine reaches all of them alike; each keeps its
best call. The reference is one timed run.

That ratio sets the kernel's best call against the reference's one run, timed minutes
apart. The "matched" line times both in alternating slices instead (three one-thread
kernel calls on the first size, then one chunk of the reference's genomes, --slices
times) and divides their mean rates, so both see the same minutes of load.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numba
import numpy as np

from linkevo.sim.linkage.evaluating import evaluate
from linkevo.sim.linkage.evaluation import Evaluation
from linkevo.sim.linkage.genome import random_genomes
from linkevo.sim.linkage.reference import evaluate_reference


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[5_000, 50_000])
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--reference-size", type=int, default=1_000)
    parser.add_argument("--mode", default="paper", choices=["paper", "legacy"])
    parser.add_argument("--slices", type=int, default=20)
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
    kernel_m, reference_m = matched_rates(
        random_genomes(rng, args.sizes[0]), genomes, args.mode, args.slices
    )
    ratio_m = kernel_m / reference_m
    print(
        f"matched   kernel {kernel_m:,.0f} and reference {reference_m:,.0f} evals/s "
        f"(means over {args.slices} alternating slices): {ratio_m:,.0f}x"
    )
    print(
        json.dumps(
            {
                "evals_per_s": round(best_2t),
                "evals_per_s_1thread": round(best_1t),
                "reference_evals_per_s": round(reference),
                "ratio_vs_reference": round(ratio, 1),
                "ratio_matched": round(ratio_m, 1),
                "mode": args.mode,
                **{k: round(v) for k, v in results.items()},
            }
        )
    )


def matched_rates(
    genomes: np.ndarray, reference_genomes: np.ndarray, mode: str, slices: int
) -> tuple[float, float]:
    """Returns the one-thread kernel's and the reference's evaluations/s, each the mean over
    `slices` alternating slices: three kernel calls on genomes (N, 56), then the next chunk
    of reference_genomes (M, 56)."""
    numba.set_num_threads(1)
    out = Evaluation.empty(genomes.shape[0], 40, 1)
    evaluate(genomes, "Fp", mode, out=out)
    kernel_s = reference_s = 0.0
    for chunk in np.array_split(reference_genomes, slices):
        start = time.perf_counter()
        for _ in range(3):
            evaluate(genomes, "Fp", mode, out=out)
        kernel_s += time.perf_counter() - start
        start = time.perf_counter()
        evaluate_reference(chunk, "Fp", mode)
        reference_s += time.perf_counter() - start
    return 3 * slices * genomes.shape[0] / kernel_s, reference_genomes.shape[0] / reference_s


if __name__ == "__main__":
    main()
