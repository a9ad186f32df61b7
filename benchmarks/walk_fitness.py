"""Benchmark: what a walked candidate costs the walking fitness F_w, against the walk map's
path, and how one F_w trial's walks scale over evaluator actors.

Run: `.venv/bin/python benchmarks/walk_fitness.py [--against TREE] [--walks 200]
[--skip-actors]`.

1. **Core-seconds per walked candidate.** One MAP-LIS F_w trial (`--walks` walked
   candidates, seed 1) runs on one core; its walk log (`walks.parquet`) says what each
   candidate it walked cost there: the search's path (`sim.robot.walk_fitness.walk_candidate`:
   the LEGO build, carpet, and flat unless the robot broke or carpet alone keeps it out
   of the archive, each walk stopped at its break). The same candidates then go through
   the walk map's path (`sim.robot.walk_map.build_cells` and `walk_legs`: the build and a 10-s
   walk on both floors, each distinct leg once), in a fresh process on one core (process
   CPU time, the layer plans' cache cleared). With `--against TREE` (another checkout,
   `git worktree add ../base REV`) TREE's walk-map path is timed too: the path as it was
   before the search walked. Goal: the search's path at most a third of the walk map's.
2. **Walks per second over evaluator actors.** The same trial on a local Ray instance
   (2 CPUs), its walks on 1 and then on 2 evaluator actors: walked candidates per wall
   second and the ratio. Goal: >= 1.7x.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
from trees import tree_env

HERE = Path(__file__).resolve().parent
MAP_PATH = """
import json, sys, time
import numpy as np
from linkevo.sim.robot.layers import _colouring
from linkevo.sim.robot.walk_map import CellBatch, LegBatch, build_cells, group_legs, walk_legs
genomes = np.load(sys.argv[1])
_colouring.cache_clear()
start = time.process_time()
built = build_cells(CellBatch(np.arange(len(genomes)), genomes, "paper", ("flat", "carpet")))
legs = group_legs(built)
walk_legs(LegBatch({str(i): g.recipe for i, g in enumerate(legs)}, ("flat", "carpet")))
print(json.dumps({"seconds": time.process_time() - start, "legs": len(legs)}))
"""


def one_core(command: list[str], env: dict[str, str]) -> str:
    """Runs a command pinned to this process's first core, numba on one thread; returns
    its standard output."""
    core = str(min(os.sched_getaffinity(0)))
    env = {**env, "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    done = subprocess.run(
        ["taskset", "-c", core, *command], env=env, capture_output=True, text=True, check=True
    )
    return done.stdout


def per_candidate(args: argparse.Namespace, work: Path) -> None:
    trial = work / "search"
    linkevo = [
        sys.executable,
        "-m",
        "linkevo.orchestrator",
        "trial",
        "--approach",
        "MAP-LIS",
        "--fitness",
        "Fw",
        "--walks",
        str(args.walks),
        "--seed",
        "1",
        "--no-progress",
        "--out",
        str(trial),
    ]
    one_core(linkevo, tree_env(HERE.parent, work))
    log = pd.read_parquet(trial / "walks.parquet")
    walked = log[log["stage"] == "walked"]
    genomes = np.stack(walked["genome"].to_numpy()).astype(np.float64)
    genomes_file = work / "candidates.npy"
    np.save(genomes_file, genomes)
    n = len(genomes)
    search = float(walked["compute_s"].sum()) / n
    skipped = walked["flat_status"].eq("not walked")
    print(
        f"{n} candidates walked by a MAP-LIS F_w trial (seed 1), one core: "
        f"{int(skipped.sum())} not walked on flat "
        f"({int((skipped & walked['flat_breaks']).sum())} broke on carpet)"
    )
    trees = [("this tree", HERE.parent)]
    if args.against is not None:
        trees.insert(0, (str(args.against), args.against))
    print(f"{'path':44s} {'core-s / candidate':>18s} {'over the search':>16s}")
    for name, tree in trees:
        out = one_core([sys.executable, "-c", MAP_PATH, str(genomes_file)], tree_env(tree, work))
        figure = json.loads(out.strip().splitlines()[-1])
        each = figure["seconds"] / n
        label = f"walk-map path ({name}, {figure['legs']} legs)"
        print(f"{label:44s} {each:18.3f} {each / search:15.2f}x")
    print(f"{'search path (the trial walk log)':44s} {search:18.3f} {1.0:15.2f}x")


def actors(args: argparse.Namespace, work: Path) -> None:
    import ray

    from linkevo.workers.evaluators import make_evaluator
    from linkevo.workers.recorders import NullRecorder
    from linkevo.workers.trial import run_trial
    from linkevo.workers.trial_spec import TrialSpec

    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False)
    rates = {}
    for k in (1, 2):
        spec = TrialSpec.walking("MAP-LIS", args.walks, seed=1)
        with make_evaluator(spec, actors=k) as evaluator:
            start = time.perf_counter()
            result = run_trial(spec, evaluator, NullRecorder(), work / f"actors{k}")
            seconds = time.perf_counter() - start
        walks = int(result.metrics["walks"])
        rates[k] = walks / seconds
        print(
            f"{k} evaluator actor(s): {walks} walked candidates in {seconds:.1f} s, "
            f"{rates[k]:.2f} walks/s"
        )
    print(f"2 actors over 1: {rates[2] / rates[1]:.2f}x")
    ray.shutdown()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", type=Path, default=None, help="another checkout to time")
    parser.add_argument("--walks", type=int, default=200)
    parser.add_argument("--skip-actors", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        per_candidate(args, Path(tmp))
        if not args.skip_actors:
            actors(args, Path(tmp))


if __name__ == "__main__":
    main()
