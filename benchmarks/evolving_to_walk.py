"""Study: evolving legs to walk (F_w) against the paper's F_p search followed by a walk map,
at one physics budget per trial (docs/results.md, "Evolving to walk").

Run: `.venv/bin/python benchmarks/evolving_to_walk.py --fw-uri URI --fw-grid GRID_ID [GRID_ID
...] --study-uri URI --study-grid GRID_ID [--walks 2000] [--trials 5] [--walkmap-times FILE]
[--out docs/results]`.

The arms: (a) MAP-LIS, (b) NSGA-II and (c) RANDOM with F_w, each trial of `--fw-grid`
(`configs/walking.toml`: `--walks` walked candidates per trial); (d) MAP-LIS with F_p at the
study's budget (the first `--trials` MAP-LIS F_p trials of `--study-grid`), each followed by
`linkevo walkmap RUN --cells best:WALKS` (its `--walks` lowest-loss cells that pass the 2-D
checks, walked 10 s on both floors). Every arm's walks are read back (an F_w trial's walk
log, a walk map's rows) and measured alike, in the shared MAP-LIS grid (`algorithms.
common_grid`: 100 x 100 cells of mean beam length x lift) so that a population and a
repertoire compare:

- best walker: the furthest worse-floor walk (cm per 10 s, credited at most the level-body
  bound, `sim.robot.walk_rows.credited_cm`) of a leg that breaks on neither floor;
- walkers: shared-grid cells holding a leg that walks at least 50 cm on both floors
  without breaking;
- walking QD-score: over the shared grid's cells, the furthest worse-floor forward walk of
  a leg that breaks on neither floor (offset 0, `algorithms.scoring.QD_OFFSETS`);
- core-seconds: an F_w trial's wall time on its one core; an F_p trial's wall time plus its
  walk map's wall time on the machine's cores (`--walkmap-times`: the lines
  `DONE RUN_ID CELLS rc=0 wall_s=S` of the script that made the maps, and `--cores`).

Pairs of arms are tested by the report's rule (`orchestrator.report.stats.pairwise_tests`,
`verdicts.judge`: two-sided Mann-Whitney U, Holm within the study's pairs and within the
pairs against RANDOM, A12 with its bootstrap interval). Writes `evolving_to_walk.csv` (a row
per trial) and `evolving_to_walk_tests.csv` to `--out` and prints the tables.
"""

from __future__ import annotations

import argparse
import re
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.algorithms.common_grid import COMMON_SPACE
from linkevo.orchestrator.report.stats import pairwise_tests
from linkevo.orchestrator.report.verdicts import judge
from linkevo.sim.linkage.descriptors import DESCRIPTOR_SPACES, bin_descriptors, cell_index
from linkevo.sim.linkage.evaluating import evaluate
from linkevo.sim.robot.hexapod import WALK_SECONDS
from linkevo.sim.robot.walk_rows import FLOOR_ORDER, WALKER_CM
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.runs import RunStore, latest_per_trial

ARM_D = "MAP-LIS, F_p + walk map"
MEASURES = ("best_walker_cm", "walkers", "walking_qd")


def worse_floor(rows: pd.DataFrame) -> np.ndarray:
    """Returns (N,) the worse floor's credited distance (`sim.robot.walk_rows.credited_cm`) of
    walk rows with `<floor>_<field>` columns, NaN where a floor was not walked or the robot
    broke on one."""
    out = np.full(len(rows), np.inf)
    for floor in FLOOR_ORDER:
        sound = (rows[f"{floor}_status"] == "walked").to_numpy() & ~rows[
            f"{floor}_breaks"
        ].to_numpy(dtype=bool)
        distance = rows[f"{floor}_mean_distance_cm"].to_numpy(dtype=float)
        bound = rows[f"{floor}_bound_cm"].to_numpy(dtype=float)
        seconds = rows[f"{floor}_seconds"].to_numpy(dtype=float)
        credited = np.where(np.isfinite(bound), np.minimum(distance, bound), distance)
        credited = credited * WALK_SECONDS / seconds
        out = np.where(sound, np.minimum(out, credited), np.nan)
    return out


def measures(genomes: np.ndarray, worse: np.ndarray, mode: str) -> dict[str, float]:
    """Returns an arm's measures for one trial's walked legs: genomes (N, 56) and their
    worse-floor distances (N,), NaN where not sound on both floors."""
    space = DESCRIPTOR_SPACES[COMMON_SPACE]
    desc = evaluate(genomes, "Fp", mode).descriptors[COMMON_SPACE]
    keep = np.isfinite(desc).all(axis=1) & np.isfinite(worse)
    cells = cell_index(bin_descriptors(desc[keep], space), space)
    best = pd.Series(worse[keep]).groupby(cells).max()
    return {
        "best_walker_cm": float(best.max()) if len(best) else 0.0,
        "walkers": int((best >= WALKER_CM).sum()),
        "walking_qd": float(best.clip(lower=0.0).sum()),
    }


def fw_arms(store: RunStore, grid: str, tmp: Path) -> list[dict]:
    runs = latest_per_trial(store.trial_table(grid))
    runs = runs[runs.status == "FINISHED"]
    out = []
    for run in runs.to_dict("records"):
        run_id = run["run_id"]
        log = pd.read_parquet(store.download(run_id, layout.WALK_LOG, tmp / run_id))
        log = log[log["stage"].isin(["walked", "cached"])]
        genomes = np.stack(log["genome"].to_numpy()).astype(np.float64)
        info = store.run(run_id).info
        out.append(
            {
                "arm": run[f"tags.{layout.APPROACH}"],
                "trial": run[f"tags.{layout.TRIAL_KEY}"],
                "walks": int((log["stage"] == "walked").sum()),
                "core_s": (info.end_time - info.start_time) / 1000,
                **measures(genomes, worse_floor(log), "paper"),
            }
        )
    return out


def walk_map_arm(
    store: RunStore, grid: str, trials: int, times: dict[str, float], cores: int, tmp: Path
) -> list[dict]:
    runs = latest_per_trial(store.trial_table(grid))
    runs = runs[(runs["tags.approach"] == "MAP-LIS") & (runs["tags.fitness"] == "Fp")]
    runs = runs.sort_values("tags.trial_key").head(trials)
    out = []
    for run in runs.to_dict("records"):
        run_id = run["run_id"]
        walks = store.walk_map(run_id, tmp / f"{run_id}-map")
        if walks is None:
            continue
        table = store.repertoire(run_id, tmp / run_id).set_index("cell")
        wide = walks.pivot(index="cell", columns="floor")
        wide.columns = [f"{floor}_{field}" for field, floor in wide.columns]
        wide = wide[(wide["flat_status"] == "walked") | (wide["carpet_status"] == "walked")]
        genomes = np.stack(table.loc[wide.index, "genome"].to_numpy()).astype(np.float64)
        info = store.run(run_id).info
        search_s = (info.end_time - info.start_time) / 1000
        out.append(
            {
                "arm": ARM_D,
                "trial": run[f"tags.{layout.TRIAL_KEY}"],
                "walks": len(wide),
                "core_s": search_s + cores * times.get(run_id, np.nan),
                **measures(genomes, worse_floor(wide.reset_index()), "paper"),
            }
        )
    return out


def first_walks(history: pd.DataFrame, reached: pd.Series) -> float:
    """Returns the walks at the first row of a trial's metrics where `reached`, NaN if none."""
    hit = history.loc[reached, "walks"]
    return float(hit.iloc[0]) if len(hit) else np.nan


def walks_to_reach(store: RunStore, fw_grid: str, surrogate_grid: str, tmp: Path) -> pd.DataFrame:
    """Returns, per MAP-LIS F_w trial index, the walks the surrogate trial (`surrogate =
    true`, the same seed) needed to reach the plain trial's final walking QD-score and best
    walker (the trials' own `qd_score` and `best_loss` in `metrics.csv`), NaN where it never
    did, and their ratio to the plain trial's walks."""

    def histories(grid: str) -> dict[str, pd.DataFrame]:
        runs = latest_per_trial(store.trial_table(grid))
        runs = runs[(runs.status == "FINISHED") & (runs[f"tags.{layout.APPROACH}"] == "MAP-LIS")]
        return {
            key: pd.read_csv(store.download(run_id, layout.METRICS_FILE, tmp / run_id))
            for key, run_id in zip(runs[f"tags.{layout.TRIAL_KEY}"], runs.run_id, strict=True)
        }

    plain, screened = histories(fw_grid), histories(surrogate_grid)
    rows = []
    for key in sorted(set(plain) & set(screened)):
        goal, guided = plain[key].iloc[-1], screened[key]

        qd = first_walks(guided, guided["qd_score"] >= goal["qd_score"])
        best = first_walks(guided, guided["best_loss"] <= goal["best_loss"])
        rows.append(
            {
                "trial": key,
                "plain_walks": goal["walks"],
                "plain_qd": goal["qd_score"],
                "surrogate_final_qd": guided["qd_score"].iloc[-1],
                "walks_to_qd": qd,
                "walks_to_best": best,
                "fewer_walks_qd": goal["walks"] / qd,
                "fewer_walks_best": goal["walks"] / best,
                "skipped": guided["walks_skipped"].iloc[-1],
            }
        )
    return pd.DataFrame(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fw-uri", required=True)
    parser.add_argument("--fw-grid", required=True, nargs="+", help="one or more F_w grids")
    parser.add_argument("--study-uri", required=True)
    parser.add_argument("--study-grid", required=True)
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--walkmap-times", type=Path, default=None)
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument(
        "--surrogate-grid",
        default=None,
        help="the same MAP-LIS F_w trials with surrogate = true, in --fw-uri",
    )
    args = parser.parse_args()
    times = {}
    if args.walkmap_times is not None:
        for line in args.walkmap_times.read_text().splitlines():
            found = re.match(r"DONE (\w+) \S+ rc=0 wall_s=(\d+)", line)
            if found:
                times[found[1]] = float(found[2])
    with tempfile.TemporaryDirectory() as tmp:
        if args.surrogate_grid:
            reach = walks_to_reach(
                RunStore.open(args.fw_uri), args.fw_grid[0], args.surrogate_grid, Path(tmp)
            )
            print("surrogate = true against plain MAP-LIS F_w (the same seeds):")
            print(reach.round(2).to_string(index=False))
            print(
                f"median fewer walks: {reach.fewer_walks_qd.median():.2f}x to the QD-score, "
                f"{reach.fewer_walks_best.median():.2f}x to the best walker"
            )
        rows = [r for g in args.fw_grid for r in fw_arms(RunStore.open(args.fw_uri), g, Path(tmp))]
        rows += walk_map_arm(
            RunStore.open(args.study_uri),
            args.study_grid,
            args.trials,
            times,
            args.cores,
            Path(tmp),
        )
    trials = pd.DataFrame(rows).assign(status="FINISHED", fitness="walk", approach=lambda f: f.arm)
    summary = trials.groupby("arm", sort=False)[[*MEASURES, "walks", "core_s"]].median()
    print("medians per arm:")
    print(summary.round(1).to_string())
    tests = []
    for measure in MEASURES:
        found = pairwise_tests(trials, measure, higher_is_better=True)
        found["verdict"] = [judge(r, lower=False) for _, r in found.iterrows()]
        tests.append(found.assign(measure=measure))
    tests = pd.concat(tests, ignore_index=True)
    cols = [
        "measure",
        "family",
        "approach_a",
        "approach_b",
        "median_a",
        "median_b",
        "a12",
        "a12_low",
        "a12_high",
        "p_holm",
        "verdict",
    ]
    print("\npairs (verdict on 'a does better than b', the report's rule):")
    print(tests[cols].round(3).to_string(index=False))
    if args.out is not None:
        trials.drop(columns=["status", "fitness", "approach"]).to_csv(
            args.out / "evolving_to_walk.csv", index=False
        )
        tests[cols].to_csv(args.out / "evolving_to_walk_tests.csv", index=False)


if __name__ == "__main__":
    main()
