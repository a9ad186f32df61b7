"""Provides `check_findings`: the study's qualitative findings tested on one grid."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.orchestrator.report.load import GridData
from linkevo.orchestrator.report.measures import trial_measures
from linkevo.orchestrator.report.stats import ALPHA, a12, a12_interval, mann_whitney, pairwise_tests
from linkevo.sim.study import (
    BASELINE,
    MULTI_OBJECTIVE,
    STUDY_EVALUATIONS,
    is_map_elites,
    is_pareto,
    label,
)
from linkevo.workers.store.artifacts import read_document

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
    "its weakest pair's verdict."
)
"""The one rule every verdict of the report follows (docs/results.md states it too)."""


@dataclass(frozen=True)
class Finding:
    """One claim of the study and what this grid says about it.

    Attributes:
        claim: the study's claim, in words.
        rule: the test applied to this grid.
        verdict: one of `STRENGTH` by `RULE`, or NOT_TESTABLE; "not judged: a pipeline
            check ..." for a grid below the study's budget.
        evidence: the numbers behind the verdict.
    """

    claim: str
    rule: str
    verdict: str
    evidence: str


def _pair(tests: pd.DataFrame, fitness: str, a: str, b: str) -> pd.Series | None:
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


def _describe(row: pd.Series, what: str = "median") -> str:
    return (
        f"{label(row.approach_a)} {what} {row.median_a:.4g} vs {label(row.approach_b)} "
        f"{row.median_b:.4g} (A12 {row.a12:.2f} [{row.a12_low:.2f}, {row.a12_high:.2f}], "
        f"Holm p {row.p_holm:.3g})"
    )


def judge(row: pd.Series, lower: bool = True) -> str:
    """Returns the verdict (`RULE`) on "approach_a does better than approach_b" from a
    test row: better is a lower measure when `lower`, else a higher one."""
    side = (lambda a: a < 0.5) if lower else (lambda a: a > 0.5)
    significant = bool(row.p_holm < ALPHA)
    if significant and side(row.a12) and side(row.a12_high if lower else row.a12_low):
        return REPRODUCED
    if significant and not side(row.a12) and not side(row.a12_low if lower else row.a12_high):
        return CONTRADICTED if row.a12 != 0.5 else NOT_REPRODUCED
    return DIRECTION_ONLY if side(row.a12) else NOT_REPRODUCED


def similar(row: pd.Series) -> str:
    """Returns the verdict (`RULE`) on "approach_a and approach_b perform alike"."""
    if bool(row.p_holm < ALPHA) and not (row.a12_low <= 0.5 <= row.a12_high):
        return NOT_REPRODUCED
    inside = row.a12_low >= 1.0 - SIMILAR_A12 and row.a12_high <= SIMILAR_A12
    return REPRODUCED if inside else NOT_SHOWN


def weakest(verdicts: list[str]) -> str:
    """Returns the weakest of several pairs' verdicts (`STRENGTH`)."""
    return max(verdicts, key=STRENGTH.index)


def _versus(
    tests: pd.DataFrame,
    claim: str,
    rule: str,
    fitness: str,
    pairs: list[tuple[str, str]],
    lower: bool = True,
    what: str = "median",
) -> Finding:
    """Returns the finding "in each pair (x, y), x does better than y" under `fitness`."""
    rows = [r for r in (_pair(tests, fitness, x, y) for x, y in pairs) if r is not None]
    if not rows:
        return Finding(claim, rule, NOT_TESTABLE, f"no finished pair of trials with {fitness}")
    verdicts = [judge(r, lower) for r in rows]
    evidence = "; ".join(f"{_describe(r, what)}: {v}" for r, v in zip(rows, verdicts, strict=True))
    return Finding(claim, rule, weakest(verdicts), evidence)


def best_path_sizes(grid: GridData) -> pd.DataFrame:
    """Returns the size of each finished trial's best-ever foot path, read from its
    best-linkage document, in model units (`../shared/spec`: 8 mm a module).

    Returns:
        Columns trial_key, approach, fitness, width, height, size (the larger of the two),
        failed_angles (the linkage's crank angles that do not assemble; the path skips
        them, which is how F_sl's best linkages reach their size, docs/results.md).
    """
    trials = grid.finished()
    rows = []
    for trial in trials[trials.best_linkage.notna()].itertuples():
        doc = read_document(Path(trial.best_linkage))
        path = doc["foot_path"]
        x, y = np.array(path["x"], dtype=float), np.array(path["y"], dtype=float)  # None: NaN
        if np.isfinite(x).any():
            width, height = np.nanmax(x) - np.nanmin(x), np.nanmax(y) - np.nanmin(y)
            size = max(width, height)
            key = (trial.trial_key, trial.approach, trial.fitness)
            rows.append((*key, width, height, size, int(doc["error"])))
    columns = ["trial_key", "approach", "fitness", "width", "height", "size", "failed_angles"]
    return pd.DataFrame(rows, columns=columns)


def check_findings(grid: GridData, tests: pd.DataFrame) -> list[Finding]:
    """Returns the study's claims, each judged on this grid's finished trials by `RULE`.

    Args:
        grid: the loaded grid.
        tests: `stats.pairwise_tests` of the grid's best losses.
    """
    approaches = grid.approaches()
    maps = [a for a in approaches if is_map_elites(a)]
    nsga = next((a for a in approaches if is_pareto(a)), MULTI_OBJECTIVE[0])
    study = tests[tests.family == "study"]
    searches = [a for a in approaches if a != BASELINE]
    measures = trial_measures(grid)
    mine = measures[measures.approach != BASELINE]
    best = f"lower median best loss; {RULE}"
    findings = [
        _versus(
            study,
            "With F_p, the MAP-Elites approaches beat the EA (Results).",
            best,
            "Fp",
            [(m, "EA") for m in maps],
        ),
        _versus(
            study,
            "With F_p, the MAP-Elites approaches slightly beat NSGA-II (Results).",
            best,
            "Fp",
            [(m, nsga) for m in maps],
        ),
        _alike(study, "Fsl"),
        _oversized(grid),
        _versus(
            study,
            "All the tested approaches except the standard EA find linkages whose path is "
            "similar to the desired one; the quality-diversity and multi-objective "
            "approaches were more efficient than the EA at it (Abstract, Conclusion).",
            best,
            "Fp",
            [(a, "EA") for a in searches if a != "EA"],
        ),
        _versus(
            pairwise_tests(mine, "stagnation", higher_is_better=True),
            "With F_p, the EA converged to a local optimum (Discussion).",
            "a larger median share of the budget spent after the last improvement of the "
            f"best loss than every other approach; {RULE}",
            "Fp",
            [("EA", a) for a in searches if a != "EA"],
            lower=False,
            what="median stagnation",
        ),
        _trade_off(measures, nsga),
    ]
    diversity = pairwise_tests(mine, "path_diversity", higher_is_better=True)
    for approach, fitness in (("MAP-WH", "Fsl"), ("MAP-AU", "Fp")):
        findings.append(
            _versus(
                diversity,
                f"With {label(fitness)}, {approach} created the most diverse paths (Results).",
                "a higher median path diversity (`sim.path_diversity`) than every other "
                f"approach; {RULE}",
                fitness,
                [(approach, a) for a in searches if a != approach],
                lower=False,
                what="median path diversity",
            )
        )
    coverage = pairwise_tests(mine, "coverage", higher_is_better=True)
    for fitness in grid.fitnesses():
        findings.append(_filled_differently(coverage, maps, fitness))
        findings.append(
            _versus(
                coverage,
                f"With {label(fitness)}, MAP-ST's structural dimensions were hard to fill "
                "(Discussion).",
                f"a lower median coverage of its own grid than every other map; {RULE}",
                fitness,
                [("MAP-ST", m) for m in maps if m != "MAP-ST"],
                what="median coverage",
            )
        )
        findings.append(
            _versus(
                pairwise_tests(mine, "descriptor_correlation", higher_is_better=True),
                f"With {label(fitness)}, MAP-WH's dimensions are correlated with the "
                "fitness (Results, prototyping).",
                "a higher median of the largest |Spearman rho| between a descriptor and "
                f"the elites' loss than every other map; {RULE}",
                fitness,
                [("MAP-WH", m) for m in maps if m != "MAP-WH"],
                lower=False,
                what="median |rho|",
            )
        )
    findings.append(_fsl_more_diverse(mine))
    if BASELINE in approaches:
        findings += _against_random(grid, tests, measures, searches)
    budget = grid.config.get("evaluations")
    if isinstance(budget, int) and budget < STUDY_EVALUATIONS:
        judged = (
            f"not judged: a pipeline check ({budget:,} of the study's "
            f"{STUDY_EVALUATIONS:,} evaluations per trial)"
        )
        findings = [dataclasses.replace(f, verdict=judged) for f in findings]
    return findings


def _alike(study: pd.DataFrame, fitness: str) -> Finding:
    """Returns the verdict on "with `fitness` all approaches perform similarly"."""
    claim = f"With {label(fitness)}, all approaches perform similarly (Results)."
    rule = f"every pair alike on best loss; {RULE}"
    rows = study[study.fitness == fitness]
    if rows.empty:
        return Finding(
            claim, rule, NOT_TESTABLE, f"fewer than two approaches finished with {fitness}"
        )
    verdicts = [similar(r) for r in rows.itertuples(index=False)]
    counts = {v: verdicts.count(v) for v in STRENGTH if v in verdicts}
    shown = [
        r for r, v in zip(rows.itertuples(index=False), verdicts, strict=True) if v != REPRODUCED
    ]
    evidence = ", ".join(f"{n} pairs {v}" for v, n in counts.items()) + (
        "; " + "; ".join(_describe(pd.Series(r._asdict())) for r in shown[:6]) if shown else ""
    )
    return Finding(claim, rule, weakest(verdicts), evidence)


def _filled_differently(coverage: pd.DataFrame, maps: list[str], fitness: str) -> Finding:
    """Returns the verdict on "the maps filled their repertoires differently": every pair
    of MAP-Elites approaches differs in own-grid coverage."""
    claim = (
        f"With {label(fitness)}, the four MAP-Elites approaches filled their repertoires "
        "quite differently (Discussion)."
    )
    rule = f"every pair of maps differs in median coverage of its own grid; {RULE}"
    pairs = [(a, b) for i, a in enumerate(maps) for b in maps[i + 1 :]]
    rows = [r for r in (_pair(coverage, fitness, a, b) for a, b in pairs) if r is not None]
    if not rows:
        return Finding(claim, rule, NOT_TESTABLE, f"no two maps finished with {fitness}")
    verdicts = [
        REPRODUCED if judge(r, lower=r.a12 < 0.5) == REPRODUCED else NOT_REPRODUCED for r in rows
    ]
    evidence = "; ".join(_describe(r, "median coverage") for r in rows)
    return Finding(claim, rule, weakest(verdicts), evidence)


def _trade_off(measures: pd.DataFrame, nsga: str) -> Finding:
    """Returns the verdict on "NSGA-II produced several linkages representing the
    trade-off between its two objectives"."""
    claim = (
        "NSGA-II produced several linkages representing the trade-off between its two "
        "objectives (Discussion)."
    )
    rule = "every finished NSGA-II trial ends with at least 3 distinct non-dominated linkages"
    fronts = measures.front_size[(measures.approach == nsga) & measures.front_size.notna()]
    if fronts.empty:
        return Finding(claim, rule, NOT_TESTABLE, "no finished NSGA-II population")
    by = measures[(measures.approach == nsga) & measures.front_size.notna()]
    medians = by.groupby("fitness").front_size.median()
    evidence = "; ".join(
        f"{label(f)}: median front {m:.0f}, smallest {by.front_size[by.fitness == f].min():.0f}"
        for f, m in medians.items()
    )
    return Finding(claim, rule, REPRODUCED if fronts.min() >= 3 else NOT_REPRODUCED, evidence)


def _fsl_more_diverse(measures: pd.DataFrame) -> Finding:
    """Returns the verdict on "F_sl could in theory lead to more diverse paths"."""
    claim = "F_sl could in theory lead to more diverse paths than F_p (Discussion)."
    rule = (
        "a higher path diversity with F_sl than with F_p, pooled over the study's "
        f"approaches; {RULE}"
    )
    return _two_samples(measures, "path_diversity", "Fsl", "Fp", claim, rule, lower=False)


def _two_samples(
    measures: pd.DataFrame,
    column: str,
    first: str,
    second: str,
    claim: str,
    rule: str,
    lower: bool,
) -> Finding:
    """Returns the verdict on "fitness `first` gives a better `column` than `second`",
    pooled over approaches (one test: Holm's p is the test's own)."""
    x = measures[column][(measures.fitness == first) & measures[column].notna()].to_numpy()
    y = measures[column][(measures.fitness == second) & measures[column].notna()].to_numpy()
    if not (x.size and y.size):
        return Finding(claim, rule, NOT_TESTABLE, f"the grid lacks finished {first} or {second}")
    _, p, _ = mann_whitney(x, y)
    low, high = a12_interval(x, y)
    row = pd.Series(
        {"approach_a": first, "approach_b": second, "median_a": float(np.median(x)),
         "median_b": float(np.median(y)), "a12": a12(x, y), "a12_low": low, "a12_high": high,
         "p_holm": p}
    )  # fmt: skip
    verdict = judge(row, lower)
    evidence = f"{_describe(row, f'median {column}')}, {x.size} and {y.size} trials"
    return Finding(claim, rule, verdict, evidence)


def _oversized(grid: GridData) -> Finding:
    """Returns the verdict on "F_sl evolves oversized linkages" via best-path sizes."""
    sizes = best_path_sizes(grid)
    sizes = sizes[sizes.approach != BASELINE]
    claim = (
        "With F_sl, the approaches created linkages that were too large to be realised "
        "(Results, Discussion)."
    )
    rule = (
        "the best-ever paths (the larger of width and height) are larger with F_sl than "
        f"with F_p, pooled over the study's approaches; {RULE}"
    )
    return _two_samples(sizes, "size", "Fsl", "Fp", claim, rule, lower=False)


def _against_random(
    grid: GridData, tests: pd.DataFrame, measures: pd.DataFrame, searches: list[str]
) -> list[Finding]:
    """Returns the baseline checks (not in the study): every search beats RANDOM on best
    loss, and MAP-LIS fills the MAP-LIS grid better than RANDOM, per fitness."""
    baseline = tests[tests.family == "baseline"]
    common = pairwise_tests(measures, "common_qd_score", higher_is_better=True)
    out = []
    for fitness in grid.fitnesses():
        out.append(
            _versus(
                baseline,
                f"With {label(fitness)}, every search beats random sampling (not in the study).",
                f"lower median best loss than RANDOM at the same budget (baseline family); {RULE}",
                fitness,
                [(a, BASELINE) for a in searches],
            )
        )
        out.append(
            _versus(
                common[common.family == "baseline"],
                f"With {label(fitness)}, MAP-LIS fills the MAP-LIS grid better than random "
                "sampling (not in the study).",
                f"higher median QD-score on the common (MAP-LIS) grid than RANDOM; {RULE}",
                fitness,
                [("MAP-LIS", BASELINE)],
                lower=False,
                what="median QD-score",
            )
        )
    return out
