"""docs/results.md says what its findings.csv tables say: each claim's verdict words in the
claims table, the count of verdicts that move from 10 to 30 trials, and "shown alike"
only where the rule shows it; and each findings.csv follows from its folder's tables."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from linkevo.orchestrator.report.findings import MEASURES
from linkevo.orchestrator.report.published import changed_claims, read_folder, table_findings
from linkevo.orchestrator.report.verdicts import NOT_TESTABLE, STRENGTH
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


@pytest.mark.parametrize("folder", COLUMNS)
def test_every_claim_recomputes_from_its_folders_tables(folder):
    """findings.csv follows, claim by claim and word for word, from the folder's
    trials.csv and path_sizes.csv alone (`linkevo findings`), the per-trial measures of
    claims 6, 7 and 12 included."""
    path = ROOT / "docs" / "results" / folder
    trials = pd.read_csv(path / "trials.csv")
    assert set(MEASURES) <= set(trials.columns)
    recomputed = table_findings(*read_folder(path))
    assert changed_claims(recomputed, findings(folder)) == []
    judged = recomputed[recomputed.number.isin(["6", "7", "12"])]
    assert len(judged) == 4 and NOT_TESTABLE not in set(judged.verdict)
