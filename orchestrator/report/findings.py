"""Provides `check_findings`: the study's qualitative findings tested on one grid."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.orchestrator.report.load import GridData
from linkevo.orchestrator.report.measures import trial_measures
from linkevo.orchestrator.report.stats import a12, a12_interval, mann_whitney, pairwise_tests
from linkevo.orchestrator.report.verdicts import (
    NOT_REPRODUCED,
    NOT_TESTABLE,
    REPRODUCED,
    RULE,
    STRENGTH,
    Finding,
    describe,
    judge,
    pair_row,
    similar,
    versus,
    weakest,
)
from linkevo.sim.study import (
    BASELINE,
    MULTI_OBJECTIVE,
    STUDY_EVALUATIONS,
    STUDY_FITNESSES,
    is_map_elites,
    is_pareto,
    label,
)
from linkevo.workers.store.artifacts import read_document


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
        versus(
            study,
            "With F_p, the MAP-Elites approaches beat the EA (Results).",
            best,
            "Fp",
            [(m, "EA") for m in maps],
        ),
        versus(
            study,
            "With F_p, the MAP-Elites approaches slightly beat NSGA-II (Results).",
            best,
            "Fp",
            [(m, nsga) for m in maps],
        ),
        _alike(study, "Fsl"),
        _oversized(grid),
        versus(
            study,
            "All the tested approaches except the standard EA find linkages whose path is "
            "similar to the desired one; the quality-diversity and multi-objective "
            "approaches were more efficient than the EA at it (Abstract, Conclusion).",
            best,
            "Fp",
            [(a, "EA") for a in searches if a != "EA"],
        ),
        versus(
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
            versus(
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
    for fitness in [f for f in grid.fitnesses() if f in STUDY_FITNESSES]:  # the paper's
        findings.append(_filled_differently(coverage, maps, fitness))
        findings.append(
            versus(
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
            versus(
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
        "; " + "; ".join(describe(pd.Series(r._asdict())) for r in shown[:6]) if shown else ""
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
    rows = [r for r in (pair_row(coverage, fitness, a, b) for a, b in pairs) if r is not None]
    if not rows:
        return Finding(claim, rule, NOT_TESTABLE, f"no two maps finished with {fitness}")
    verdicts = [
        REPRODUCED if judge(r, lower=r.a12 < 0.5) == REPRODUCED else NOT_REPRODUCED for r in rows
    ]
    evidence = "; ".join(describe(r, "median coverage") for r in rows)
    return Finding(claim, rule, weakest(verdicts), evidence)


def _trade_off(measures: pd.DataFrame, nsga: str) -> Finding:
    """Returns the verdict on "NSGA-II produced several linkages representing the
    trade-off between its two objectives"."""
    claim = (
        "NSGA-II produced several linkages representing the trade-off between its two "
        "objectives (Discussion)."
    )
    rule = "every finished NSGA-II trial ends with at least 3 distinct non-dominated linkages"
    by = measures[
        (measures.approach == nsga)
        & measures.front_size.notna()
        & measures.fitness.isin(STUDY_FITNESSES)  # the paper's objectives
    ]
    fronts = by.front_size
    if fronts.empty:
        return Finding(claim, rule, NOT_TESTABLE, "no finished NSGA-II population")
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
    evidence = f"{describe(row, f'median {column}')}, {x.size} and {y.size} trials"
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
            versus(
                baseline,
                f"With {label(fitness)}, every search beats random sampling (not in the study).",
                f"lower median best loss than RANDOM at the same budget (baseline family); {RULE}",
                fitness,
                [(a, BASELINE) for a in searches],
            )
        )
        out.append(
            versus(
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
