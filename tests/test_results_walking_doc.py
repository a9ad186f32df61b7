"""docs/results.md's walking and Table I sections say what their tables in docs/results/ say:
every median and range of the arms' table, every range and A12 the prose quotes, every
verdict word beside a pair, and the Table I section's medians, counts and verdicts."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from linkevo.orchestrator.report.verdicts import judge

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"
DOC = (ROOT / "docs" / "results.md").read_text()
ARMS = {
    "MAP-LIS": "(a) MAP-LIS, F_w",
    "NSGA2": "(b) NSGA-II, F_w",
    "RANDOM": "(c) RANDOM, F_w",
    "MAP-LIS, F_p + walk map": "(d) MAP-LIS, F_p + walk map",
}
"""The arms of evolving_to_walk.csv, as the doc's table names them."""
F_W_ARMS = ("MAP-LIS", "NSGA2", "RANDOM")
IN_PROSE = {"MAP-LIS": "MAP-LIS F_w", "NSGA2": "NSGA-II", "RANDOM": "RANDOM"}
"""How the verdicts' prose names an arm."""


def section(title: str, level: str = "## ") -> str:
    start = DOC.index(f"{level}{title}")
    end = DOC.find(f"\n{level}", start + 1)
    return DOC[start : end if end > 0 else None]


def number(text: str) -> float:
    return float(text.replace(",", ""))


def spread(values: pd.Series, decimals: int) -> tuple[str, str, str]:
    """The median and range of per-trial values as the doc writes them."""
    fmt = (lambda v: f"{v:,.{decimals}f}") if decimals else (lambda v: f"{round(v):,}")
    ends = (lambda v: f"{round(v):,}") if decimals else fmt
    return fmt(values.median()), ends(values.min()), ends(values.max())


WALKING = section("Evolving to walk")
TRIALS = pd.read_csv(RESULTS / "evolving_to_walk.csv")
TESTS = pd.read_csv(RESULTS / "evolving_to_walk_tests.csv")


def arms_table() -> dict[str, list[str]]:
    """The arms' table: its cells per arm (best walker, walkers, walking QD-score)."""
    rows = {}
    for line in WALKING.splitlines():
        cells = [c.strip().replace("**", "") for c in line.strip().strip("|").split("|")]
        if cells and cells[0] in ARMS.values() and len(cells) == 5:
            rows[cells[0]] = cells[1:4]
    return rows


@pytest.mark.parametrize("arm", list(ARMS))
def test_the_arms_table_is_the_trials_medians_and_ranges(arm):
    cells = arms_table()[ARMS[arm]]
    mine = TRIALS[TRIALS.arm == arm]
    for cell, column, decimals in zip(
        cells, ("best_walker_cm", "walkers", "walking_qd"), (1, 0, 0), strict=True
    ):
        median, low, high = spread(mine[column], decimals)
        assert cell == f"{median} ({low}–{high})", (arm, column)


def test_the_prose_ranges_of_walkers_are_the_arms():
    walkers = TRIALS[TRIALS.arm.isin(F_W_ARMS)].walkers
    quoted = re.findall(r"(\d[\d,]*)–(\d[\d,]*)\)? for any F_w arm", WALKING)
    quoted += re.findall(r"cells against (\d[\d,]*)–(\d[\d,]*)\)", DOC)
    assert quoted
    for low, high in quoted:
        assert (number(low), number(high)) == (walkers.min(), walkers.max())


def verdicts() -> pd.DataFrame:
    """The tests with the rule's verdict recomputed from their A12 and Holm p."""
    return TESTS.assign(rule=[judge(row, lower=False) for _, row in TESTS.iterrows()])


def test_the_verdicts_csv_is_the_rule_applied():
    table = verdicts()
    assert (table.rule == table.verdict).all()


def test_every_a12_the_walking_prose_quotes_is_a_test_of_the_table():
    table = verdicts()
    known = {f"{v:.2f}" for v in np.concatenate([table.a12, 1 - table.a12])}
    intervals = {
        f"[{lo:.2f}, {hi:.2f}]"
        for lo, hi in zip(
            np.concatenate([table.a12_low, 1 - table.a12_high]),
            np.concatenate([table.a12_high, 1 - table.a12_low]),
            strict=True,
        )
    }
    prose = section("Evolving to walk").split("### The search in the model")[0]
    for a12, interval in re.findall(r"A12 (\d\.\d\d)( \[\d\.\d\d, \d\.\d\d\])?", prose):
        assert a12 in known, a12
        if interval:
            assert interval.strip() in intervals, interval


def test_a_pairs_verdict_word_is_its_rule():
    table = verdicts()
    said = re.findall(
        r"(MAP-LIS F_w|NSGA-II|RANDOM) against (MAP-LIS F_w|NSGA-II|RANDOM): ([a-z ]+) \(A12",
        WALKING,
    )
    assert said
    names = {v: k for k, v in IN_PROSE.items()}
    for a, b, word in said:
        rows = table[(table.approach_a == names[a]) & (table.approach_b == names[b])]
        assert word in set(rows.rule), (a, b, word)


def test_the_smallest_separation_shown_is_the_one_stated():
    table = verdicts()
    shown = table[table.rule.isin(["reproduced", "contradicted"])]
    nearest = np.minimum(shown.a12, 1 - shown.a12).max()
    stated = re.search(r"shown only near complete separation, at A12 (\d\.\d\d) or beyond", WALKING)
    assert stated and float(stated.group(1)) == pytest.approx(1 - nearest)
    assert "only a complete separation" not in WALKING


TABLE_ONE = section("Prototyping, predicted: Table I on the simulated robot")
PREDICTED = pd.read_csv(RESULTS / "paper" / "table1_predicted.csv")
VERDICTS = pd.read_csv(RESULTS / "paper" / "table1_verdicts.csv")
PAPER_CM = {
    ("MAP-WH", "first"): (73.6, 63.6),
    ("MAP-LIS", "modified"): (40.4, 48.0),
    ("MAP-ST", "first"): (39.4, 39.6),
    ("MAP-ST", "modified"): (77.6, 39.0),
    ("MAP-AU", "first"): (61.8, 59.4),
    ("MAP-AU", "modified"): (51.0, 50.0),
}
"""The paper's Table I: the six robots that walked, (flat, carpet) cm in 10 s."""


def robot_row(approach: str, robot: str) -> str:
    """The Table I section's row of one robot, from table1_predicted.csv: the median distance
    per floor (lean, full in brackets, over the draws with one), the draws that walk on
    both floors, and the draws with no modification possible."""
    rows = PREDICTED[(PREDICTED.approach == approach) & (PREDICTED.robot == robot)]
    none = rows.rule.astype(str).str.startswith("no modification possible")
    built = rows[~none]
    cells = [approach, robot]
    for floor in ("flat", "carpet"):
        medians = []
        for model in ("lean", "full"):
            cm = pd.to_numeric(
                built[(built.floor == floor) & (built.model == model)].mean_distance_cm,
                errors="coerce",
            ).dropna()
            medians.append(f"{cm.median():.1f}" if len(cm) else "none")
        cells.append(f"{medians[0]} ({medians[1]})")
    walking = []
    for model in ("lean", "full"):
        mine = built[built.model == model]
        walks = ~mine.breaks.astype(str).eq("True") & (
            pd.to_numeric(mine.mean_distance_cm, errors="coerce").fillna(-np.inf) > 10.0
        )
        both = walks.groupby(mine.draw).all()
        walking.append(int(both.sum()))
    draws = built.draw.nunique()
    cells.append(f"{walking[0]} ({walking[1]}) of {draws}")
    cells.append(str(rows[none].draw.nunique()))
    paper = PAPER_CM.get((approach, robot))
    cells.append(f"{paper[0]} / {paper[1]}" if paper else "did not walk")
    return "| " + " | ".join(cells) + " |"


def test_the_table_one_rows_are_the_predictions():
    for approach in ("MAP-WH", "MAP-LIS", "MAP-ST", "MAP-AU"):
        for robot in ("first", "modified"):
            assert robot_row(approach, robot) in TABLE_ONE, robot_row(approach, robot)


def verdict_row(row: pd.Series) -> str:
    counts = [re.findall(r"(\d+ of \d+) draws", row[f"evidence_{m}"]) for m in ("lean", "full")]
    said = "; ".join(counts[0]) + (
        f" (full: {'; '.join(counts[1])})" if counts[1] != counts[0] else ""
    )
    return f"| {row.claim} | {row.verdict_lean} | {row.verdict_full} | {said} |"


def test_the_table_one_verdicts_are_the_csvs():
    for _, row in VERDICTS.iterrows():
        assert verdict_row(row) in TABLE_ONE, verdict_row(row)


def test_the_table_one_ratios_to_the_paper_are_the_medians():
    """ "N to M times as far": the simulated medians (lean, both floors) of the robots the
    paper saw walk, over the paper's own distances."""
    ratios = []
    for (approach, robot), paper in PAPER_CM.items():
        rows = PREDICTED[
            (PREDICTED.approach == approach)
            & (PREDICTED.robot == robot)
            & (PREDICTED.model == "lean")
        ]
        for floor, cm in zip(("flat", "carpet"), paper, strict=True):
            sim = pd.to_numeric(rows[rows.floor == floor].mean_distance_cm, errors="coerce")
            if sim.notna().any():
                ratios.append(sim.median() / cm)
    stated = re.search(r"go (\d\.\d) to (\d\.\d) times\s+as far", TABLE_ONE)
    assert stated, "the section states the ratio to the paper's distances"
    assert (float(stated.group(1)), float(stated.group(2))) == (
        round(min(ratios), 1),
        round(max(ratios), 1),
    )


def test_one_grid_is_named_for_table_one():
    named = set(re.findall(r"`([0-9a-f]{12})`", TABLE_ONE))
    assert len(named) == 1
    elsewhere = re.findall(r"`([0-9a-f]{12})` for\s+Table I", DOC)
    assert elsewhere and set(elsewhere) == named


SAIL_ARMS = {
    "plain": "plain",
    "screen": "screen",
    "sail": "SAIL",
    "sail-head": "SAIL, head start",
}
"""benchmarks/sail.py's arms, as the SAIL table names them."""


def sail_row(arm: str) -> str:
    """The SAIL table's row of one arm, from sail_trials.csv: medians (ranges) over its
    trials of the walking QD-score at 200, 500 and 2,000 walks, the walks to reach the
    plain arm's final QD-score of the same seed (how many reach it), and a trial's wall
    and CPU minutes (CPU where the benchmark measured it)."""
    trials = pd.read_csv(RESULTS / "sail_trials.csv")
    mine = trials[trials.arm == arm]
    cells = [SAIL_ARMS[arm], str(len(mine))]
    for n in (200, 500, 2000):
        values = mine[f"qd@{n}"].dropna()
        cells.append(
            f"{values.median():,.0f} ({values.min():,.0f}–{values.max():,.0f})"
            if len(values)
            else "–"
        )
    reach = mine.to_reach_plain.dropna()
    cells.append(
        f"{reach.median():,.0f} ({len(reach)} of {len(mine)})"
        if len(reach)
        else f"0 of {len(mine)}"
    )
    cpu = mine.cpu_s.dropna()
    cells.append(f"{mine.wall_s.median() / 60:.1f}")
    cells.append(f"{cpu.median() / 60:.1f} ({len(cpu)} of {len(mine)})" if len(cpu) else "–")
    return "| " + " | ".join(cells) + " |"


def test_the_sail_table_is_the_benchmarks_trials():
    sail = section("The search in the model (SAIL)", "### ")
    for arm in SAIL_ARMS:
        assert sail_row(arm) in sail, sail_row(arm)
