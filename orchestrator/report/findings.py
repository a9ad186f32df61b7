"""Provides `check_findings`: the study's qualitative findings tested on one grid."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.orchestrator.report.load import GridData
from linkevo.orchestrator.report.stats import ALPHA
from linkevo.sim.study import (
    BASELINE,
    MULTI_OBJECTIVE,
    STUDY_EVALUATIONS,
    is_map_elites,
    is_pareto,
    label,
)

REPRODUCED = "reproduced"
NOT_REPRODUCED = "not reproduced"
NOT_TESTABLE = "not testable"
NO_DIFFERENCE = "no difference found"
"""The verdict on a claim of similarity when no pair differs: absence of evidence of a
difference at this grid's number of trials, not evidence of similarity."""
HOLDS = "holds"
DOES_NOT_HOLD = "does not hold"
"""Verdicts of the checks that are linkevo's own, not the study's claims."""


@dataclass(frozen=True)
class Finding:
    """One claim of the study and what this grid says about it.

    Attributes:
        claim: the study's claim, in words.
        rule: the test applied to this grid.
        verdict: REPRODUCED, NOT_REPRODUCED, NO_DIFFERENCE or NOT_TESTABLE (HOLDS or
            DOES_NOT_HOLD for linkevo's own checks); "not judged: a pipeline check ..." for
            a grid below the study's budget.
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
    return row


def _describe(row: pd.Series) -> str:
    return (
        f"{label(row.approach_a)} median {row.median_a:.4g} vs {label(row.approach_b)} "
        f"{row.median_b:.4g} (A12 {row.a12:.2f}, Holm p {row.p_holm:.3g})"
    )


def _map_versus(
    tests: pd.DataFrame, fitness: str, maps: list[str], other: str, significant: bool
) -> tuple[str, str]:
    """Returns (verdict, evidence) for "every MAP-Elites approach beats `other`".

    Beating means a lower median best loss; with `significant` also a Holm-corrected
    Mann–Whitney p below ALPHA.
    """
    rows = [_pair(tests, fitness, m, other) for m in maps]
    rows = [r for r in rows if r is not None]
    if not rows:
        return NOT_TESTABLE, f"no finished MAP-Elites and {label(other)} trials with {fitness}"
    wins = [r.median_a < r.median_b and (not significant or bool(r.p_holm < ALPHA)) for r in rows]
    verdict = REPRODUCED if all(wins) else NOT_REPRODUCED
    return verdict, "; ".join(_describe(r) for r in rows)


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
        doc = json.loads(Path(trial.best_linkage).read_text())
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
    """Returns the study's findings, each checked on this grid's finished trials.

    Args:
        grid: the loaded grid.
        tests: `stats.pairwise_tests` of the grid.
    """
    approaches = grid.approaches()
    maps = [a for a in approaches if is_map_elites(a)]
    nsga = next((a for a in approaches if is_pareto(a)), MULTI_OBJECTIVE[0])
    study = tests[tests.family == "study"]
    findings = []

    verdict, evidence = _map_versus(study, "Fp", maps, "EA", significant=True)
    findings.append(
        Finding(
            claim="With F_p, the MAP-Elites approaches beat the EA.",
            rule=(
                "every MAP-Elites approach has a lower median best loss than EA and a "
                f"Holm-corrected Mann–Whitney p < {ALPHA}"
            ),
            verdict=verdict,
            evidence=evidence,
        )
    )
    verdict, evidence = _map_versus(study, "Fp", maps, nsga, significant=False)
    findings.append(
        Finding(
            claim="With F_p, the MAP-Elites approaches slightly beat NSGA-II.",
            rule="every MAP-Elites approach has a lower median best loss than NSGA-II",
            verdict=verdict,
            evidence=evidence,
        )
    )
    fsl = study[study.fitness == "Fsl"]
    if fsl.empty:
        verdict, evidence = NOT_TESTABLE, "fewer than two approaches finished with Fsl"
    else:
        differing = fsl[fsl.significant]
        verdict = NO_DIFFERENCE if differing.empty else NOT_REPRODUCED
        shown = differing if len(differing) else fsl.loc[[fsl.p_holm.idxmin()]]
        n = int(min(fsl.n_a.min(), fsl.n_b.min()))
        evidence = (
            f"{len(differing)} of {len(fsl)} pairs differ at n = {n} or more trials per "
            "approach (no equivalence margin is tested, so this is no evidence of "
            "similarity); " + "; ".join(_describe(r) for r in shown.itertuples(index=False))
        )
    findings.append(
        Finding(
            claim="With F_sl, all approaches perform similarly.",
            rule=f"no pair of approaches differs (every Holm-corrected p >= {ALPHA})",
            verdict=verdict,
            evidence=evidence,
        )
    )
    findings.append(_oversized(grid))
    if BASELINE in approaches:
        findings += _against_random(grid, tests, [a for a in approaches if a != BASELINE])
    budget = grid.config.get("evaluations")
    if isinstance(budget, int) and budget < STUDY_EVALUATIONS:
        judged = (
            f"not judged: a pipeline check ({budget:,} of the study's "
            f"{STUDY_EVALUATIONS:,} evaluations per trial)"
        )
        findings = [dataclasses.replace(f, verdict=judged) for f in findings]
    return findings


def _against_random(grid: GridData, tests: pd.DataFrame, searches: list[str]) -> list[Finding]:
    """Returns the baseline checks: every search beats RANDOM on best loss, per fitness,
    and MAP-LIS covers the MAP-LIS grid better than RANDOM does (the one MAP-Elites grid
    RANDOM's archive shares)."""
    baseline = tests[tests.family == "baseline"]
    out = []
    for fitness in grid.fitnesses():
        rows = [_pair(baseline, fitness, a, BASELINE) for a in searches]
        rows = [r for r in rows if r is not None]
        claim = f"With {label(fitness)}, every search beats random sampling (not in the study)."
        rule = (
            "every approach has a lower median best loss than RANDOM at the same budget and a "
            f"Holm-corrected Mann–Whitney p < {ALPHA} (baseline family)"
        )
        if not rows:
            out.append(Finding(claim, rule, NOT_TESTABLE, f"no finished pairs with {fitness}"))
            continue
        wins = [r.median_a < r.median_b and bool(r.p_holm < ALPHA) for r in rows]
        verdict = HOLDS if all(wins) else DOES_NOT_HOLD
        out.append(Finding(claim, rule, verdict, "; ".join(_describe(r) for r in rows)))
    done = grid.finished()
    for fitness in grid.fitnesses():
        cell = done[done.fitness == fitness]
        lis = cell[cell.approach == "MAP-LIS"]
        rnd = cell[cell.approach == BASELINE]
        claim = (
            f"With {label(fitness)}, MAP-LIS fills its grid better than random sampling "
            "(not in the study)."
        )
        rule = "MAP-LIS's median coverage and QD-score exceed RANDOM's on the MAP-LIS grid"
        if lis.empty or rnd.empty:
            out.append(Finding(claim, rule, NOT_TESTABLE, "no finished MAP-LIS or RANDOM trials"))
            continue
        medians = {
            name: (frame.coverage.median(), frame.qd_score.median())
            for name, frame in (("MAP-LIS", lis), (BASELINE, rnd))
        }
        better = all(m > r for m, r in zip(medians["MAP-LIS"], medians[BASELINE], strict=True))
        evidence = "; ".join(
            f"{name} median coverage {c:.4f}, QD-score {q:.4g}" for name, (c, q) in medians.items()
        )
        out.append(Finding(claim, rule, HOLDS if better else DOES_NOT_HOLD, evidence))
    return out


def _oversized(grid: GridData) -> Finding:
    """Returns the check of "F_sl tends to evolve oversized linkages" via best-path sizes."""
    sizes = best_path_sizes(grid)
    sizes = sizes[sizes.approach != BASELINE]
    claim = "F_sl tends to evolve oversized linkages."
    rule = (
        "the median size of the best-ever paths (max of width and height) is larger with "
        "F_sl than with F_p, over the study's approaches"
    )
    by_fitness = sizes.groupby("fitness")["size"].median()
    if not {"Fp", "Fsl"} <= set(by_fitness.index):
        return Finding(claim, rule, NOT_TESTABLE, "the grid lacks finished Fp or Fsl trials")
    verdict = REPRODUCED if by_fitness["Fsl"] > by_fitness["Fp"] else NOT_REPRODUCED
    evidence = (
        f"median best-path size {by_fitness['Fsl']:.3g} with F_sl vs "
        f"{by_fitness['Fp']:.3g} with F_p (units)"
    )
    return Finding(claim, rule, verdict, evidence)
