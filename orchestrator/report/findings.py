"""Provides `check_findings`: the study's qualitative findings tested on one grid."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pandas as pd

from linkevo.orchestrator.report.load import finished_trials
from linkevo.orchestrator.report.stats import (
    a12,
    a12_interval,
    holm,
    mann_whitney,
    median_interval,
    pairwise_tests,
)
from linkevo.orchestrator.report.verdicts import (
    NOT_REPRODUCED,
    NOT_TESTABLE,
    REPRODUCED,
    RULE,
    STRENGTH,
    Finding,
    above,
    describe,
    judge,
    pair_row,
    similar,
    versus,
    weakest,
)
from linkevo.sim.study import (
    APPROACHES,
    BASELINE,
    FITNESSES,
    MULTI_OBJECTIVE,
    STUDY_EVALUATIONS,
    STUDY_FITNESSES,
    is_map_elites,
    is_pareto,
    label,
    ordered,
)

HIGH_CORRELATION = 0.7
"""|rho| from which a correlation is called high (Hinkle, Wiersma and Jurs, "Applied
Statistics for the Behavioral Sciences": 0.7-0.9 high, above 0.9 very high)."""
HIGH_DEPENDENCE = 3 / math.pi * math.asin((1 + HIGH_CORRELATION**2) / 2) - 0.5
"""Chatterjee's xi from which a dependence is called high: the xi of a bivariate normal
pair at |rho| = `HIGH_CORRELATION` (its limit (3/pi) asin((1 + rho^2) / 2) - 1/2, about
0.30), so that a peaked dependence as strong as a high monotone one reads high."""
MEASURES: tuple[str, ...] = (
    "stagnation",
    "descriptor_correlation",
    "descriptor_dependence",
    "front_size",
)
"""The per-trial measures `trial_measures` adds; `trials.csv` of a report carries them."""


def check_findings(
    trials: pd.DataFrame, sizes: pd.DataFrame, tests: pd.DataFrame, budget: object
) -> list[Finding]:
    """Returns the study's claims, each judged on a grid's finished trials by `RULE`, as
    the paper states it (its exceptions, "highly", "in theory").

    Args:
        trials: the grid's trials with the `MEASURES` columns (`trial_measures`), as a
            report's `trials.csv` holds them.
        sizes: `best_path_sizes` of the grid (a report's `path_sizes.csv`).
        tests: `stats.pairwise_tests` of the grid's best losses.
        budget: the grid's evaluations per trial; below the study's, nothing is judged.
    """
    approaches = ordered(trials.approach.unique(), APPROACHES)
    fitnesses = ordered(trials.fitness.unique(), FITNESSES)
    maps = [a for a in approaches if is_map_elites(a)]
    nsga = next((a for a in approaches if is_pareto(a)), MULTI_OBJECTIVE[0])
    study = tests[tests.family == "study"]
    searches = [a for a in approaches if a != BASELINE]
    measures = finished_trials(trials)
    mine = measures[measures.approach != BASELINE]
    best = f"lower median best loss; {RULE}"
    findings = [
        versus(
            study,
            "1",
            "With F_p, the MAP-Elites approaches beat the EA (Results).",
            best,
            "Fp",
            [(m, "EA") for m in maps],
        ),
        versus(
            study,
            "2",
            "With F_p, the MAP-Elites approaches slightly beat NSGA-II (Results).",
            best,
            "Fp",
            [(m, nsga) for m in maps],
        ),
        _alike(study, "Fsl"),
        _oversized(sizes[sizes.approach != BASELINE], nsga),
        versus(
            study,
            "5",
            "All the tested approaches except the standard EA find linkages whose path is "
            "similar to the desired one; the quality-diversity and multi-objective "
            "approaches were more efficient than the EA at it (Abstract, Conclusion).",
            best,
            "Fp",
            [(a, "EA") for a in searches if a != "EA"],
        ),
        versus(
            pairwise_tests(mine, "stagnation", higher_is_better=True),
            "6",
            "With F_p, the EA seemed to converge to a local optimum (Discussion).",
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
    for number, approach, fitness in (("8", "MAP-WH", "Fsl"), ("9", "MAP-AU", "Fp")):
        findings.append(
            versus(
                diversity,
                number,
                f"With {label(fitness)}, {approach} seems to have created more diverse paths "
                "(Results; judged: more diverse than each other approach's).",
                "a higher median path diversity (`sim.linkage.path_diversity`) than every other "
                f"approach; {RULE}",
                fitness,
                [(approach, a) for a in searches if a != approach],
                lower=False,
                what="median path diversity",
            )
        )
    common = pairwise_tests(mine, "common_coverage", higher_is_better=True)
    coverage = pairwise_tests(mine, "coverage", higher_is_better=True)
    for fitness in [f for f in fitnesses if f in STUDY_FITNESSES]:  # the paper's
        findings.append(_filled_differently(common, maps, fitness))
        findings.append(
            versus(
                coverage,
                "11",
                f"With {label(fitness)}, MAP-ST's structural dimensions were difficult to "
                "define in a way that filled the entire map (Discussion).",
                f"a lower median coverage of its own grid than every other map; {RULE}",
                fitness,
                [("MAP-ST", m) for m in maps if m != "MAP-ST"],
                what="median coverage",
            )
        )
        findings.append(_highly_correlated(mine, fitness))
    findings.append(_fsl_more_diverse(mine, searches))
    if BASELINE in approaches:
        findings += _against_random(measures, tests, fitnesses, searches)
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
            "3", fitness, claim, rule, NOT_TESTABLE, "fewer than two approaches finished"
        )
    verdicts = [similar(r) for r in rows.itertuples(index=False)]
    counts = {v: verdicts.count(v) for v in STRENGTH if v in verdicts}
    shown = [
        r for r, v in zip(rows.itertuples(index=False), verdicts, strict=True) if v != REPRODUCED
    ]
    evidence = ", ".join(f"{n} pairs {v}" for v, n in counts.items()) + (
        "; " + "; ".join(describe(pd.Series(r._asdict())) for r in shown[:6]) if shown else ""
    )
    return Finding("3", fitness, claim, rule, weakest(verdicts), evidence)


def _filled_differently(common: pd.DataFrame, maps: list[str], fitness: str) -> Finding:
    """Returns the verdict on "the maps filled their repertoires differently": every pair
    of MAP-Elites approaches differs in coverage of the common grid (each trial's elites
    placed on MAP-LIS's grid), the one coverage that compares across approaches."""
    claim = (
        f"With {label(fitness)}, the four MAP-Elites approaches filled the repertoires "
        "quite differently (Discussion)."
    )
    rule = (
        "every pair of maps differs in median coverage of the common (MAP-LIS) grid; an own "
        f"grid's coverage does not compare across approaches; {RULE}"
    )
    pairs = [(a, b) for i, a in enumerate(maps) for b in maps[i + 1 :]]
    rows = [r for r in (pair_row(common, fitness, a, b) for a, b in pairs) if r is not None]
    if not rows:
        return Finding("10", fitness, claim, rule, NOT_TESTABLE, "no two maps finished")
    verdicts = [
        REPRODUCED if judge(r, lower=r.a12 < 0.5) == REPRODUCED else NOT_REPRODUCED for r in rows
    ]
    evidence = "; ".join(describe(r, "median common coverage") for r in rows)
    return Finding("10", fitness, claim, rule, weakest(verdicts), evidence)


def _highly_correlated(measures: pd.DataFrame, fitness: str) -> Finding:
    """Returns the verdict on "MAP-WH's dimensions are highly correlated with the
    fitness": over MAP-WH's trials, the median of the largest |Spearman rho| between a
    descriptor and the elites' loss against `HIGH_CORRELATION`, and the median of the
    largest Chatterjee xi (which sees a peaked dependence, "a path of a certain size")
    against `HIGH_DEPENDENCE`; the stronger of the two verdicts (a trials table without
    xi, from before it was measured, is judged on rho alone and says so)."""
    claim = (
        f"With {label(fitness)}, the width and height, MAP-WH's dimensions, are highly "
        "correlated with the fitness (Prototyping, Discussion)."
    )
    rule = (
        "over MAP-WH's trials, the median of the largest |Spearman rho| between a descriptor "
        f"and the elites' loss is high (above {HIGH_CORRELATION}), or the median of the "
        f"largest Chatterjee xi of the loss on a descriptor is (above {HIGH_DEPENDENCE:.2f}, "
        f"the xi of a normal pair at rho {HIGH_CORRELATION}); the stronger verdict; {RULE}"
    )
    mine = measures[(measures.approach == "MAP-WH") & (measures.fitness == fitness)]
    rhos = mine.descriptor_correlation.dropna()
    if rhos.size < 2:
        return Finding("12", fitness, claim, rule, NOT_TESTABLE, "fewer than two MAP-WH trials")
    median = float(rhos.median())
    low, high = median_interval(rhos.to_numpy())
    verdicts = [above(median, low, high, HIGH_CORRELATION)]
    others = (
        measures[
            measures.approach.map(is_map_elites)
            & (measures.approach != "MAP-WH")
            & (measures.fitness == fitness)
        ]
        .groupby("approach")
        .descriptor_correlation.median()
    )
    evidence = (
        f"MAP-WH median |rho| {median:.2f} [{low:.2f}, {high:.2f}] over {rhos.size} trials"
        + "".join(f"; {a} {m:.2f}" for a, m in others.dropna().items())
    )
    xis = mine.get("descriptor_dependence", pd.Series(dtype=float)).dropna()
    if xis.size >= 2:
        xi = float(xis.median())
        xi_low, xi_high = median_interval(xis.to_numpy())
        verdicts.append(above(xi, xi_low, xi_high, HIGH_DEPENDENCE))
        evidence += f"; MAP-WH median xi {xi:.2f} [{xi_low:.2f}, {xi_high:.2f}]"
    else:
        evidence += "; xi not measured in this trials table"
    strongest = min(verdicts, key=STRENGTH.index)
    return Finding("12", fitness, claim, rule, strongest, evidence)


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
        return Finding("7", "", claim, rule, NOT_TESTABLE, "no finished NSGA-II population")
    medians = by.groupby("fitness").front_size.median()
    evidence = "; ".join(
        f"{label(f)}: median front {m:.0f}, smallest {by.front_size[by.fitness == f].min():.0f}"
        for f, m in medians.items()
    )
    verdict = REPRODUCED if fronts.min() >= 3 else NOT_REPRODUCED
    return Finding("7", "", claim, rule, verdict, evidence)


def _fsl_more_diverse(measures: pd.DataFrame, searches: list[str]) -> Finding:
    """Returns the verdict on "F_sl could in theory lead to more diverse paths", judged
    per approach (pooling would hide approaches that go opposite ways)."""
    claim = (
        "F_sl could in theory lead to more diverse paths than F_p, since it allows more "
        "room for how to achieve its properties (Discussion; the paper's conjecture, "
        "which its own runs did not bear out)."
    )
    rule = (
        "for every study approach, a higher path diversity with F_sl than with F_p "
        f"(Holm over the approaches); {RULE}"
    )
    return _fitness_versus(
        "13", measures, "path_diversity", searches, ("Fsl", "Fp"), claim, rule, lower=False
    )


def _fitness_versus(
    number: str,
    measures: pd.DataFrame,
    column: str,
    approaches: list[str],
    fitnesses: tuple[str, str],
    claim: str,
    rule: str,
    lower: bool,
) -> Finding:
    """Returns the verdict on "for each approach, the first fitness gives a better
    `column` than the second" (a Mann–Whitney test per approach, Holm over them)."""
    first, second = fitnesses
    rows = []
    for approach in approaches:
        mine = measures[(measures.approach == approach) & measures[column].notna()]
        x = mine[column][mine.fitness == first].to_numpy()
        y = mine[column][mine.fitness == second].to_numpy()
        if x.size and y.size:
            low, high = a12_interval(x, y)
            rows.append(
                {
                    "approach_a": f"{label(approach)} {label(first)}",
                    "approach_b": label(second),
                    "median_a": float(np.median(x)),
                    "median_b": float(np.median(y)),
                    "a12": a12(x, y),
                    "a12_low": low,
                    "a12_high": high,
                    "p": mann_whitney(x, y)[1],
                }
            )
    if not rows:
        return Finding(number, "", claim, rule, NOT_TESTABLE, "no approach has both fitnesses")
    table = pd.DataFrame(rows)
    table["p_holm"] = holm(table.p.to_numpy())
    verdicts = [judge(r, lower) for _, r in table.iterrows()]
    evidence = "; ".join(
        f"{describe(r, f'median {column}')}: {v}"
        for (_, r), v in zip(table.iterrows(), verdicts, strict=True)
    )
    return Finding(number, "", claim, rule, weakest(verdicts), evidence)


def _oversized(sizes: pd.DataFrame, nsga: str) -> Finding:
    """Returns the verdict on "with the exception of NSGA-II, all approaches created
    linkages too large to be realised with F_sl", from best-path sizes: every approach
    but NSGA-II has larger best paths with F_sl than with F_p, and NSGA-II's F_sl paths
    are smaller than every other approach's."""
    claim = (
        "With the exception of NSGA-II, all approaches created linkages that were too large "
        "to be successfully realised on the robot when combined with F_sl (Results)."
    )
    rule = (
        "for every approach but NSGA-II, larger best-ever paths (the larger of width and "
        "height) with F_sl than with F_p (Holm over the approaches), and NSGA-II's F_sl "
        f"paths smaller than every other approach's (the study family); {RULE}"
    )
    others = ordered([a for a in sizes.approach.unique() if a != nsga], APPROACHES)
    larger = _fitness_versus("4", sizes, "size", others, ("Fsl", "Fp"), claim, rule, lower=False)
    if larger.verdict == NOT_TESTABLE:
        return larger
    exception = versus(
        pairwise_tests(sizes.assign(status="FINISHED"), "size"),
        "4",
        claim,
        rule,
        "Fsl",
        [(nsga, a) for a in others],
        what="median size",
    )
    verdict = weakest([v for v in (larger.verdict, exception.verdict) if v != NOT_TESTABLE])
    evidence = f"{larger.evidence}; the exception: {exception.evidence}"
    return Finding("4", "", claim, rule, verdict, evidence)


def _against_random(
    measures: pd.DataFrame, tests: pd.DataFrame, fitnesses: list[str], searches: list[str]
) -> list[Finding]:
    """Returns the baseline checks (not in the study): every search beats RANDOM on best
    loss, and MAP-LIS fills the MAP-LIS grid better than RANDOM, per fitness."""
    baseline = tests[tests.family == "baseline"]
    common = pairwise_tests(measures, "common_qd_score", higher_is_better=True)
    out = []
    for fitness in fitnesses:
        out.append(
            versus(
                baseline,
                "R1",
                f"With {label(fitness)}, every search beats random sampling (not in the study).",
                f"lower median best loss than RANDOM at the same budget (baseline family); {RULE}",
                fitness,
                [(a, BASELINE) for a in searches],
            )
        )
        out.append(
            versus(
                common[common.family == "baseline"],
                "R2",
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
