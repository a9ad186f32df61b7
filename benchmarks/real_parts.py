"""Benchmark: what real Technic parts do to a study's legs (`sim.robot.parts`).

1. **Buildable with real parts** (`--tracking-uri URI`, a grid's MAP-Elites F_p trials): of
   each map's cells that pass the 2-D checks, a sample (`--sample` per map, seeded) is
   built as `linkevo pull` builds it; printed per map: how many real parts build, and why
   the others fail (no whole-module rounding, no layer plan keeping every beam off the pins
   and axles it passes, a pin, bush or overhang striking a beam).
2. **The walk's change** (`--against TREE`, another checkout: the code before real parts):
   the study cells of `tests/data/study_cells.json` (legs real parts build), each walked
   10 s on both floors on the lean model by both trees; printed per cell and floor, the
   distance before and after, and the median change.

Run: `.venv/bin/python benchmarks/real_parts.py [--tracking-uri URI [--grid ID]]
[--against TREE] [--sample 200]` (about 3 minutes for the share at 200 a map, 2 for the walks).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from trees import tree_env

os.environ.setdefault("MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR", "false")

HERE = Path(__file__).resolve().parents[1]
CELLS = HERE / "tests" / "data" / "study_cells.json"
WALKER = """
import json, sys
import numpy as np
from linkevo.sim.robot.hexapod import FLOORS
from linkevo.sim.robot.leg import leg_from_genome
from linkevo.sim.robot.walking import WalkSettings, walk
out = []
for cell in json.load(open(sys.argv[1])):
    leg = leg_from_genome(np.array(cell["genome"]), cell["mode"])
    for floor in ("flat", "carpet"):
        w = walk(leg, FLOORS[floor], settings=WalkSettings(seconds=10.0))
        out.append([cell["trial"], cell["cell"], floor, w.distance_m * 100, w.breaks])
print(json.dumps(out))
"""


def share(uri: str, grid: str | None, sample: int) -> None:
    """Prints, per map, how many of a sample of 2-D-buildable cells real parts build."""
    from linkevo.sim import decode, simulate
    from linkevo.sim.linkage.physical import physical_checks
    from linkevo.sim.robot.leg import LegError, recipe_and_leg
    from linkevo.workers.store.runs import RunStore

    store = RunStore(uri, "linkevo")
    trials = [t for t in store.repertoires(store.grid(grid)[0]).trials if t.fitness == "Fp"]
    rng = np.random.default_rng(0)
    found: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for trial in trials:
        with tempfile.TemporaryDirectory() as tmp:
            table = store.repertoire(trial.run_id, Path(tmp))
        genomes = np.stack(table["genome"].to_numpy())
        batch = decode(genomes, trial.mode)
        ok = np.flatnonzero(physical_checks(batch, simulate(batch, 40)).buildable)
        per_trial = max(1, sample // sum(t.approach == trial.approach for t in trials))
        counts = found[trial.approach]
        for i in rng.choice(ok, size=min(per_trial, len(ok)), replace=False):
            counts["sampled"] += 1
            try:
                recipe, _ = recipe_and_leg(genomes[i], trial.mode)
            except LegError:
                counts["does not turn"] += 1
                continue
            note = recipe.note
            if not note:
                counts["real parts build it"] += 1
            elif "rounding" in note:
                counts["no whole-module rounding"] += 1
            elif "each must lie further out" in note:
                counts["no layer plan: two beams each pass a frame axle through the other"] += 1
            elif "no plan" in note:
                counts["no layer plan keeps the pins clear"] += 1
            else:
                counts["a pin, bush or overhang strikes"] += 1
    print("## buildable with real parts (cells that pass the 2-D checks)")
    for approach, counts in found.items():
        built = counts["real parts build it"]
        print(
            f"{approach:8s} {built:4d} of {counts['sampled']:4d} ({built / counts['sampled']:.0%})"
        )
        for reason, n in counts.most_common():
            if reason not in ("sampled", "real parts build it"):
                print(f"           {n:4d} {reason}")


def walks(tree: Path, work: Path) -> dict[tuple, tuple[float, bool]]:
    """Walks the study cells on a tree; returns (trial, cell, floor) -> (cm, breaks)."""
    work.mkdir(parents=True, exist_ok=True)
    script = work / "walk.py"
    script.write_text(WALKER)
    done = subprocess.run(
        [sys.executable, str(script), str(CELLS)],
        env=tree_env(tree, work),
        check=True,
        capture_output=True,
        text=True,
    )
    return {(t, c, f): (cm, breaks) for t, c, f, cm, breaks in json.loads(done.stdout)}


def change(against: Path) -> None:
    """Prints each study cell's walk before (`against`) and after (this tree)."""
    with tempfile.TemporaryDirectory() as tmp:
        before = walks(against.resolve(), Path(tmp) / "before")
        after = walks(HERE, Path(tmp) / "after")
    print(f"## the walk with real parts: {against} (before) against this tree (after)")
    diffs: dict[str, list[float]] = {"flat": [], "carpet": []}
    sound: dict[str, list[float]] = {"flat": [], "carpet": []}
    broke = collections.Counter()
    for key in sorted(before):
        (b, b_breaks), (a, a_breaks) = before[key], after[key]
        flags = ("before breaks " if b_breaks else "") + ("after breaks" if a_breaks else "")
        print(f"{key[0]:14s} {key[1]:6d} {key[2]:6s} {b:7.1f} cm -> {a:7.1f} cm  {flags}")
        diffs[key[2]].append(a - b)
        broke[key[2], "before"] += b_breaks
        broke[key[2], "after"] += a_breaks
        if not (b_breaks or a_breaks):
            sound[key[2]].append(a - b)
    for floor, values in diffs.items():
        print(
            f"{floor}: median change {np.median(values):+.1f} cm, middle half "
            f"{np.percentile(values, 25):+.1f} to {np.percentile(values, 75):+.1f} cm, "
            f"{len(values)} cells; breaks {broke[floor, 'before']} before, "
            f"{broke[floor, 'after']} after; the {len(sound[floor])} that break in neither: "
            f"median change {np.median(sound[floor]):+.1f} cm"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tracking-uri", default=None, help="a store with a study grid")
    parser.add_argument("--grid", default=None, help="the grid (default: the latest)")
    parser.add_argument("--sample", type=int, default=200, help="cells per map")
    parser.add_argument("--against", type=Path, default=None, help="another checkout")
    args = parser.parse_args()
    if args.tracking_uri:
        share(args.tracking_uri, args.grid, args.sample)
    if args.against:
        change(args.against)


if __name__ == "__main__":
    main()
