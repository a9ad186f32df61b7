"""Benchmark: does a walking trial's best walker walk on the full model as the lean model
credited it?

Runs F_w trials (MAP-LIS and NSGA-II, seeds 1..K, `--walks` each) with `linkevo trial`,
on this tree and, with `--against TREE`, on another checkout (the lean model before a
change); then walks each trial's best linkage on the full model from 5 hand-placed starts
per floor, 10 s each (`sim.robot.confirmation.confirm_walk`, this tree's full model), and
prints, per trial and floor, the distance the trial credited its best (the lean search
walk, cm per 10 s, at most the level-body bound) beside the full model's mean, and how
many trials agree within 30 % on both floors (a floor where both break agrees).

Run: `.venv/bin/python benchmarks/lean_vs_full.py [--against TREE] [--walks 300]
[--trials 5]` (about 25 minutes of two cores per tree at 300 walks).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from trees import tree_env

from linkevo.sim.linkage.linkage_doc import from_document
from linkevo.sim.robot.confirmation import confirm_walk
from linkevo.sim.robot.leg import leg_from_genome
from linkevo.sim.robot.walk_rows import FLOOR_FIELDS, FLOOR_ORDER, Status, credited_cm

HERE = Path(__file__).resolve().parents[1]
APPROACHES = ("MAP-LIS", "NSGA2")


def run_trials(tree: Path, work: Path, walks: int, trials: int) -> list[Path]:
    """Runs the trials on `tree`, two at a time; returns their folders."""
    jobs = [(a, s) for a in APPROACHES for s in range(1, trials + 1)]
    env = tree_env(tree, work)

    def one(job: tuple[str, int]) -> Path:
        approach, seed = job
        out = work / f"{approach}-{seed}"
        words = f"trial --approach {approach} --fitness Fw --walks {walks} --seed {seed}"
        command = [sys.executable, "-m", "linkevo.orchestrator", *words.split()]
        command += ["--out", str(out), "--no-progress"]
        subprocess.run(command, env=env, check=True, capture_output=True)
        return out

    with ThreadPoolExecutor(2) as pool:
        return list(pool.map(one, jobs))


def credited(folder: Path) -> tuple[np.ndarray, dict[str, float | None]]:
    """A trial's best genome and the distance its walk log credits it per floor (None where
    it broke or was not walked)."""
    genome, _ = from_document(json.loads((folder / "best_linkage.json").read_text()))
    log = pd.read_parquet(folder / "walks.parquet")
    at = [i for i, g in enumerate(log["genome"]) if np.array_equal(g, genome)]
    out: dict[str, float | None] = dict.fromkeys(FLOOR_ORDER)
    if at:
        for floor in FLOOR_ORDER:
            row = {f: log[f"{floor}_{f}"].iloc[at[-1]] for f in FLOOR_FIELDS}
            if row["status"] == Status.WALKED and not row["breaks"]:
                out[floor] = credited_cm(row)
    return genome, out


def measure(tree: Path, walks: int, trials: int) -> list[dict]:
    with tempfile.TemporaryDirectory() as tmp:
        rows = []
        for folder in run_trials(tree, Path(tmp), walks, trials):
            genome, lean = credited(folder)
            check = confirm_walk(leg_from_genome(genome), lean)
            for f in check.floors:
                rows.append(
                    {
                        "trial": folder.name,
                        "floor": f.floor,
                        "lean_cm": f.lean_cm,
                        "full_cm": f.full_mean_cm,
                        "full_breaks": f.full_breaks,
                        "chaotic": f.chaotic,
                        "agrees": f.agrees,
                    }
                )
        return rows


def report(name: str, rows: list[dict]) -> None:
    frame = pd.DataFrame(rows)
    print(f"## {name}")
    for r in frame.itertuples():
        lean = "breaks" if r.lean_cm is None or pd.isna(r.lean_cm) else f"{r.lean_cm:7.1f}"
        full = "breaks" if r.full_breaks else f"{r.full_cm:7.1f}"
        flags = ("agrees" if r.agrees else "DISAGREES") + (", chaotic" if r.chaotic else "")
        print(f"{r.trial:12s} {r.floor:7s} credited {lean:>7s} cm  full {full:>7s} cm  {flags}")
    both = frame.groupby("trial")["agrees"].all()
    print(f"{int(both.sum())} of {len(both)} best walkers agree within 30 % on both floors\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--against", type=Path, default=None, help="another checkout")
    parser.add_argument("--walks", type=int, default=300)
    parser.add_argument("--trials", type=int, default=5, help="trials per approach")
    args = parser.parse_args()
    if args.against is not None:
        report(f"before: {args.against}", measure(args.against.resolve(), args.walks, args.trials))
    report(f"this tree: {HERE}", measure(HERE, args.walks, args.trials))


if __name__ == "__main__":
    main()
