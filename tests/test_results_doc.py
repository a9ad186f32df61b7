"""docs/results.md says what its findings.csv tables say: each claim's verdict words in the
claims table, the count of verdicts that move from 10 to 30 trials, and "shown alike"
only where the rule shows it."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from linkevo.orchestrator.report.verdicts import STRENGTH
from linkevo.sim.study import label

ROOT = Path(__file__).resolve().parents[1]
DOC = (ROOT / "docs" / "results.md").read_text()
COLUMNS = ("paper_10", "paper", "legacy_10", "legacy")
"""The claims table's verdict columns, left to right, as folders of docs/results/."""
WORDS = ("no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten")
SIMILARITY_SLIPS = (
    "the same as",
    "level with",
    "as diverse as",
    "as correlated as",
    "ties exactly",
)
"""Ways of calling two approaches alike that the rule never licenses."""


def findings(folder: str) -> pd.DataFrame:
    table = pd.read_csv(ROOT / "docs" / "results" / folder / "findings.csv", dtype=str)
    return table.fillna("")


def section(title: str) -> str:
    start = DOC.index(f"## {title}")
    end = DOC.find("\n## ", start + 1)
    return DOC[start : end if end > 0 else None]


def claims_table() -> dict[str, list[str]]:
    """Returns the claims table's verdict cells per claim number."""
    rows = {}
    for line in section("The paper's claims, one by one").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 2 + len(COLUMNS) or not line.startswith("| ") or cells[0] == "claim":
            continue
        number = re.match(r"(\d+)\.", cells[0])
        if number:
            rows[number.group(1)] = cells[2:]
        elif "beats random sampling" in cells[0]:
            rows["R1"] = cells[2:]
        elif "fills the MAP-LIS grid" in cells[0]:
            rows["R2"] = cells[2:]
    return rows


def test_every_claim_of_findings_csv_is_in_the_table():
    numbers = set(findings("paper").number)
    assert numbers == set(claims_table()), "a claim is missing from the table or from findings.csv"


@pytest.mark.parametrize("column", range(len(COLUMNS)))
def test_the_claims_table_says_each_verdict_of_findings_csv(column):
    table = findings(COLUMNS[column])
    for number, cells in claims_table().items():
        cell = cells[column].lower()
        rows = table[table.number == number]
        verdicts = set(rows.verdict)
        assert verdicts <= set(STRENGTH), (number, verdicts)
        if len(verdicts) == 1:
            (verdict,) = verdicts
            assert cell.startswith(verdict), (COLUMNS[column], number, verdict, cell)
        else:
            for fitness, verdict in zip(rows.fitness, rows.verdict, strict=True):
                said = f"{label(fitness)} {verdict}".lower()
                assert said in cell, (COLUMNS[column], number, said, cell)


@pytest.mark.parametrize("mode", ["paper", "legacy"])
def test_the_count_of_verdicts_that_move_at_30_trials_is_true(mode):
    ten, thirty = findings(f"{mode}_10"), findings(mode)
    moved = int((ten.verdict != thirty.verdict).sum())
    said = re.search(rf"In {mode} mode\s+(\w+)\s+verdicts?\s+moves?", section("The paper's claims"))
    assert said, f"the {mode} paragraph names no count"
    assert WORDS.index(said.group(1)) == moved


def test_shown_alike_only_where_the_rule_shows_it():
    text = DOC.lower()
    for slip in SIMILARITY_SLIPS:
        assert slip not in text, slip
    counts = {
        int(m.group(1))
        for folder in COLUMNS
        for evidence in findings(folder).query("number == '3'").evidence
        for m in [re.match(r"(\d+) pairs reproduced", evidence)]
        if m
    } | {0}
    for said in re.findall(r"(\w+) pairs (?:are )?shown alike", text):
        assert WORDS.index(said) in counts, said
