"""Provides the one rule every verdict of the report follows (`RULE`), the verdicts it
gives, and how a claim over pairs of approaches is judged by it (`versus`)."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from linkevo.orchestrator.report.stats import ALPHA
from linkevo.sim.study import label

REPRODUCED = "reproduced"
DIRECTION_ONLY = "direction only"
NOT_REPRODUCED = "not reproduced"
CONTRADICTED = "contradicted"
NOT_SHOWN = "not shown"
NOT_TESTABLE = "not testable"
STRENGTH: tuple[str, ...] = (REPRODUCED, DIRECTION_ONLY, NOT_SHOWN, NOT_REPRODUCED, CONTRADICTED)
"""Verdicts from strongest to weakest: a claim over several pairs takes its weakest."""
SIMILAR_A12 = 0.71
"""A12 within [1 - 0.71, 0.71]: less than Vargha and Delaney's large effect ("similar")."""
RULE = (
    "A claim that X does better than Y on a per-trial measure is reproduced when A12 of X "
    "over Y lies on the claimed side of 0.5, its 95 % bootstrap interval excludes 0.5 and "
    f"the Holm-corrected two-sided Mann–Whitney p < {ALPHA}; direction only when A12 is on "
    "the claimed side without both; contradicted when the reverse holds with both; "
    "otherwise not reproduced. A claim of similarity is reproduced when every pair's A12 "
    f"interval lies within [{1 - SIMILAR_A12:.2f}, {SIMILAR_A12}] (less than a large effect), "
    "not reproduced when a pair differs by the first rule, and otherwise not shown (the "
    "intervals are too wide at this number of trials). A claim over several pairs takes "
    "its weakest pair's verdict. A claim that a measure is high is reproduced when the 95 % "
    "bootstrap interval of its median lies above the level, direction only when the median "
    "does without the interval, contradicted when the interval lies below, otherwise not "
    "reproduced."
)
"""The one rule every verdict of the report follows (docs/results.md states it too)."""


@dataclass(frozen=True)
class Finding:
    """One claim of the study and what this grid says about it.

    Attributes:
        number: the claim's number in docs/results.md ("1".."13"; "R1", "R2" for the
            checks against random sampling, which are not the study's).
        fitness: the fitness the finding is judged under; "" for a claim across both.
        claim: the study's claim, in words.
        rule: the test applied to this grid.
        verdict: one of `STRENGTH` by `RULE`, or NOT_TESTABLE; "not judged: a pipeline
            check ..." for a grid below the study's budget.
        evidence: the numbers behind the verdict.
    """

    number: str
    fitness: str
    claim: str
    rule: str
    verdict: str
    evidence: str


def pair_row(tests: pd.DataFrame, fitness: str, a: str, b: str) -> pd.Series | None:
    """Returns the test row comparing approaches a and b under `fitness`, a first."""
    rows = tests[(tests.fitness == fitness)]
    hit = rows[(rows.approach_a == a) & (rows.approach_b == b)]
    if len(hit):
        return hit.iloc[0]
    hit = rows[(rows.approach_a == b) & (rows.approach_b == a)]
    if not len(hit):
        return None
    row = hit.iloc[0].copy()
    row["approach_a"], row["approach_b"] = a, b
    row["median_a"], row["median_b"] = row.median_b, row.median_a
    row["a12"] = 1.0 - row.a12
    row["a12_low"], row["a12_high"] = 1.0 - row.a12_high, 1.0 - row.a12_low
    return row


def describe(row: pd.Series, what: str = "median") -> str:
    return (
        f"{label(row.approach_a)} {what} {row.median_a:.4g} vs {label(row.approach_b)} "
        f"{row.median_b:.4g} (A12 {row.a12:.2f} [{row.a12_low:.2f}, {row.a12_high:.2f}], "
        f"Holm p {row.p_holm:.3g})"
    )


def judge(row: pd.Series, lower: bool = True) -> str:
    """Returns the verdict (`RULE`) on "approach_a does better than approach_b" from a
    test row: better is a lower measure when `lower`, else a higher one."""
    side = (lambda a: a < 0.5) if lower else (lambda a: a > 0.5)
    other = (lambda a: a > 0.5) if lower else (lambda a: a < 0.5)
    significant = bool(row.p_holm < ALPHA)
    if significant and side(row.a12) and side(row.a12_high if lower else row.a12_low):
        return REPRODUCED
    if significant and other(row.a12) and other(row.a12_low if lower else row.a12_high):
        return CONTRADICTED  # the interval excludes 0.5 on the other side
    return DIRECTION_ONLY if side(row.a12) else NOT_REPRODUCED


def similar(row: pd.Series) -> str:
    """Returns the verdict (`RULE`) on "approach_a and approach_b perform alike"."""
    if bool(row.p_holm < ALPHA) and not (row.a12_low <= 0.5 <= row.a12_high):
        return NOT_REPRODUCED
    inside = row.a12_low >= 1.0 - SIMILAR_A12 and row.a12_high <= SIMILAR_A12
    return REPRODUCED if inside else NOT_SHOWN


def above(median: float, low: float, high: float, level: float) -> str:
    """Returns the verdict (`RULE`) on "the measure is high": its median and the 95 %
    interval of the median (`stats.median_interval`) against `level`."""
    if low > level:
        return REPRODUCED
    if high < level:
        return CONTRADICTED
    return DIRECTION_ONLY if median > level else NOT_REPRODUCED


def weakest(verdicts: list[str]) -> str:
    """Returns the weakest of several pairs' verdicts (`STRENGTH`)."""
    return max(verdicts, key=STRENGTH.index)


def versus(
    tests: pd.DataFrame,
    number: str,
    claim: str,
    rule: str,
    fitness: str,
    pairs: list[tuple[str, str]],
    lower: bool = True,
    what: str = "median",
) -> Finding:
    """Returns the finding "in each pair (x, y), x does better than y" under `fitness`."""
    rows = [r for r in (pair_row(tests, fitness, x, y) for x, y in pairs) if r is not None]
    if not rows:
        return Finding(
            number, fitness, claim, rule, NOT_TESTABLE, f"no finished pair of trials with {fitness}"
        )
    verdicts = [judge(r, lower) for r in rows]
    evidence = "; ".join(f"{describe(r, what)}: {v}" for r, v in zip(rows, verdicts, strict=True))
    return Finding(number, fitness, claim, rule, weakest(verdicts), evidence)
