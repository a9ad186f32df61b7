"""Benchmark: SAIL (`surrogate = "sail"`) against plain MAP-LIS F_w and the walk model's
screen, at the same seeds.

Arms (MAP-LIS, F_w, seeds 1..K, `linkevo trial` each, two at a time):
- plain: `--walks` (2,000) walks of the plain search;
- screen: the same with `--surrogate screen`;
- sail: `--surrogate sail` from scratch, `--sail-walks` walks;
- sail-head: the same with a head start, `--walk-model RUN_ID` of `--tracking-uri`.

A trial already in WORK (its result.json written) is read, not run again, so an arm can be
run ahead with the same command. Reported per arm: the walks each trial took to reach the
plain arm's final walking QD-score of its seed (median over the seeds), the walking
QD-score and best walker (cm per 10 s on the worse floor) at 200, 500 and 2,000 walks
(the first iteration at or past them; "-" where the trial stopped before), and each trial's
wall and CPU seconds (the trial process's own, from `os.wait4`).

The prediction map's honesty (the SAIL arms): `--sample` cells per trial of its prediction
map that the trial never walked, drawn at random, are built and walked now with the
walking fitness's walk on both floors: Spearman of predicted against walked distance per
floor (cells that walked there without breaking), how many real parts cannot build, and,
of the cells predicted to walk at least 50 cm on both floors (and of those also predicted
not to break, p_break < 0.5 on each), the share that do and how many real parts build.

Run: `.venv/bin/python benchmarks/sail.py --work DIR [--walks 2000] [--sail-walks 500]
[--seeds 5] [--walk-model RUN_ID --tracking-uri URI] [--arms plain,screen,sail,sail-head]
[--tables docs/results]` (the last writes every trial's row, `sail_trials.csv`, and each SAIL
arm's honesty, `sail_honesty.csv`).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import spearmanr

from linkevo.sim.robot.walk_fitness import walk_candidate
from linkevo.sim.robot.walk_rows import FLOOR_ORDER, WALKER_CM, Stage, Status, credited_cm

CHECKPOINTS = (200, 500, 2000)


def run_trial(out: Path, walks: int, seed: int, extra: list[str]) -> dict:
    """Runs one trial into `out` (unless it is there); returns its wall and CPU seconds."""
    timing = out.with_suffix(".time.json")
    if (out / "result.json").exists():  # run ahead: its own timing, else its wall time
        if timing.exists():
            return json.loads(timing.read_text())
        seconds = json.loads((out / "result.json").read_text())["seconds"]
        return {"wall_s": seconds, "cpu_s": np.nan}
    words = ["trial", "--approach", "MAP-LIS", "--fitness", "Fw", "--walks", str(walks)]
    words += ["--seed", str(seed), "--out", str(out), "--no-progress", *extra]
    start = time.perf_counter()
    process = subprocess.Popen(
        [sys.executable, "-m", "linkevo.orchestrator", *words],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    _, status, usage = os.wait4(process.pid, 0)
    if status:
        raise RuntimeError(f"{out.name}: {process.stderr.read().decode()[-2000:]}")
    seconds = {"wall_s": time.perf_counter() - start, "cpu_s": usage.ru_utime + usage.ru_stime}
    timing.write_text(json.dumps(seconds))
    return seconds


def at_walks(metrics: pd.DataFrame, walks: int) -> tuple[float, float]:
    """Returns (walking QD-score, best walker cm) at the first iteration with `walks`."""
    reached = metrics[metrics["walks"] >= walks]
    if reached.empty:
        return np.nan, np.nan
    row = reached.iloc[0]
    return float(row["qd_score"]), float(-row["best_loss"])


def walks_to_reach(metrics: pd.DataFrame, target: float) -> float:
    """Returns the walks a trial took to reach a walking QD-score (NaN: never)."""
    reached = metrics[metrics["qd_score"] >= target]
    return float(reached["walks"].iloc[0]) if len(reached) else np.nan


def walk_cell(genome: np.ndarray) -> dict[str, object]:
    """Walks one predicted cell's leg now: its stage and credited cm per floor (NaN where
    it breaks or no leg builds)."""
    walked = walk_candidate(genome, "paper")
    out: dict[str, object] = {"stage": str(walked.stage), **dict.fromkeys(FLOOR_ORDER, np.nan)}
    if walked.stage == Stage.WALKED:
        for row in walked.rows:
            if row["status"] == Status.WALKED and not row["breaks"]:
                out[row["floor"]] = credited_cm(row)
    return out


def honesty(folders: list[Path], sample: int, seed: int) -> dict[str, float]:
    """Walks `sample` never-walked cells of each trial's prediction map; returns the
    figures: Spearman per floor over the cells that walked there soundly, how many real
    parts did not build, and of the cells predicted to walk `WALKER_CM` on both floors
    without breaking (p_break < 0.5 on each), how many do."""
    rng = np.random.default_rng(seed)
    picked = []
    for folder in folders:
        table = pd.read_parquet(folder / "prediction_map.parquet")
        never = table[~table["walked"]]
        picked.append(never.iloc[rng.choice(len(never), min(sample, len(never)), replace=False)])
    cells = pd.concat(picked, ignore_index=True)
    genomes = np.stack(cells["genome"].to_numpy()).astype(np.float64)
    with ProcessPoolExecutor(2) as pool:
        walked = pd.DataFrame(list(pool.map(walk_cell, genomes, chunksize=4)))
    figures: dict[str, float] = {"cells": float(len(cells))}
    figures["no_build"] = float((walked["stage"] != str(Stage.WALKED)).sum())
    for floor in FLOOR_ORDER:
        sound = walked[floor].notna().to_numpy()
        rho = spearmanr(cells[f"{floor}_predicted_cm"][sound], walked[floor][sound]).statistic
        figures[f"spearman_{floor}"] = float(rho)
        figures[f"walked_{floor}"] = float(sound.sum())
    far = (cells[[f"{f}_predicted_cm" for f in FLOOR_ORDER]] >= WALKER_CM).all(axis=1)
    sound = (cells[[f"{f}_p_break" for f in FLOOR_ORDER]] < 0.5).all(axis=1)
    kept = (walked[list(FLOOR_ORDER)].fillna(-np.inf) >= WALKER_CM).all(axis=1)
    figures["far"] = float(far.sum())
    figures["far_kept"] = float((far & kept).sum())
    built = (walked["stage"] == str(Stage.WALKED)).to_numpy()
    figures["promised"] = float((far & sound).sum())
    figures["promised_kept"] = float((far & sound & kept).sum())
    figures["promised_built"] = float((far & sound & built).sum())
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, required=True, help="the trials' folder")
    parser.add_argument("--walks", type=int, default=2000, help="plain and screen arms")
    parser.add_argument("--sail-walks", type=int, default=500, help="the SAIL arms")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--sample", type=int, default=20, help="cells walked per SAIL trial")
    parser.add_argument("--walk-model", default="", help="the head start's run id")
    parser.add_argument("--tracking-uri", default=None, help="the head start's store")
    parser.add_argument("--arms", default="plain,screen,sail,sail-head")
    parser.add_argument(
        "--tables", type=Path, default=None, help="write sail_trials.csv and sail_honesty.csv here"
    )
    args = parser.parse_args()
    store = ["--tracking-uri", args.tracking_uri] if args.tracking_uri else []
    arms = {
        "plain": (args.walks, []),
        "screen": (args.walks, ["--surrogate", "screen"]),
        "sail": (args.sail_walks, ["--surrogate", "sail"]),
        "sail-head": (
            args.sail_walks,
            ["--surrogate", "sail", "--walk-model", args.walk_model, *store],
        ),
    }
    chosen = [a for a in args.arms.split(",") if a != "sail-head" or args.walk_model]
    jobs = [(arm, seed) for arm in chosen for seed in range(1, args.seeds + 1)]
    args.work.mkdir(parents=True, exist_ok=True)

    def one(job: tuple[str, int]) -> dict:
        arm, seed = job
        walks, extra = arms[arm]
        return run_trial(args.work / f"{arm}-{seed}", walks, seed, extra)

    with ThreadPoolExecutor(2) as pool:
        timings = dict(zip(jobs, pool.map(one, jobs), strict=True))
    metrics = {job: pd.read_csv(args.work / f"{job[0]}-{job[1]}" / "metrics.csv") for job in jobs}
    targets = {
        seed: float(metrics[("plain", seed)]["qd_score"].iloc[-1])
        for seed in range(1, args.seeds + 1)
        if ("plain", seed) in metrics
    }
    print(f"plain arm's final walking QD-score per seed: {targets}")
    trials, honest = [], []
    for arm in chosen:
        rows = []
        for seed in range(1, args.seeds + 1):
            m = metrics[(arm, seed)]
            row = {"seed": seed, "walks": int(m["walks"].iloc[-1])}
            row["to_reach_plain"] = walks_to_reach(m, targets.get(seed, np.inf))
            for n in CHECKPOINTS:
                row[f"qd@{n}"], row[f"best@{n}"] = at_walks(m, n)
            row |= timings[(arm, seed)]
            rows.append(row)
        table = pd.DataFrame(rows)
        trials.append(table.assign(arm=arm))
        print(f"\n## {arm}")
        print(table.to_string(index=False, float_format=lambda v: f"{v:.1f}"))
        print(
            f"median walks to reach plain's final QD-score: {table['to_reach_plain'].median():.0f} "
            f"({table['to_reach_plain'].notna().sum()} of {len(table)} reach it); medians: "
            + ", ".join(f"QD@{n} {table[f'qd@{n}'].median():.0f}" for n in CHECKPOINTS)
            + f"; wall {table['wall_s'].median():.0f} s, CPU {table['cpu_s'].median():.0f} s"
        )
        if arm.startswith("sail"):
            folders = [args.work / f"{arm}-{s}" for s in range(1, args.seeds + 1)]
            figures = honesty(folders, args.sample, seed=len(arm))
            honest.append({"arm": arm, **figures})
            print(
                f"prediction map honesty: {figures['cells']:.0f} never-walked cells walked now; "
                + ", ".join(
                    f"Spearman {f} {figures[f'spearman_{f}']:.2f} "
                    f"({figures[f'walked_{f}']:.0f} walked soundly)"
                    for f in FLOOR_ORDER
                )
                + f"; real parts build no leg for {figures['no_build']:.0f}; predicted >= "
                f"{WALKER_CM:.0f} cm on both floors: {figures['far']:.0f} (of which "
                f"{figures['far_kept']:.0f} walk it), and without breaking: "
                f"{figures['promised']:.0f} (of which {figures['promised_kept']:.0f} walk it; "
                f"real parts build {figures['promised_built']:.0f})"
            )
    if args.tables is not None:
        args.tables.mkdir(parents=True, exist_ok=True)
        pd.concat(trials).to_csv(args.tables / "sail_trials.csv", index=False)
        pd.DataFrame(honest).to_csv(args.tables / "sail_honesty.csv", index=False)


if __name__ == "__main__":
    main()
