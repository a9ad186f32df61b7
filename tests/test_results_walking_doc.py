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
