"""The report's statistics and header on hand-made trial tables (no store needed)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.stats import mannwhitneyu

from linkevo.orchestrator.report.html import context
from linkevo.orchestrator.report.stats import (
    a12,
    a12_interval,
    mann_whitney,
    pairwise_tests,
    summary_table,
)
from linkevo.orchestrator.report.verdicts import (
    CONTRADICTED,
    DIRECTION_ONLY,
    NOT_REPRODUCED,
    NOT_SHOWN,
    REPRODUCED,
    judge,
    similar,
    weakest,
)


def trials(losses: dict[tuple[str, str], list[float]]) -> pd.DataFrame:
    """Returns a GridData.trials-like table of FINISHED trials with these best losses."""
    rows = [
        {"approach": a, "fitness": f, "status": "FINISHED", "best_loss": loss}
        for (a, f), values in losses.items()
        for loss in values
    ]
    return pd.DataFrame(rows)


def test_mann_whitney_is_exact_without_ties_and_asymptotic_with_them():
    x, y = np.arange(10.0), np.arange(10.0) + 4.5
    u, p, method = mann_whitney(x, y)
    exact = mannwhitneyu(x, y, alternative="two-sided", method="exact")
    assert method == "exact" and (u, p) == (exact.statistic, exact.pvalue)
    assert mannwhitneyu(x, y, alternative="two-sided").pvalue != p  # scipy's default differs
    tied = np.append(x[:-1], 5.5)
    _, p_tied, method = mann_whitney(tied, y)
    assert method == "asymptotic"
    assert p_tied == mannwhitneyu(tied, y, alternative="two-sided", method="asymptotic").pvalue


def test_random_forms_its_own_holm_family():
    rng = np.random.default_rng(0)
    table = trials(
        {
            ("EA", "Fp"): list(rng.normal(20, 1, 10)),
            ("MAP-LIS", "Fp"): list(rng.normal(15, 1, 10)),
            ("NSGA2", "Fp"): list(rng.normal(16, 1, 10)),
            ("RANDOM", "Fp"): list(rng.normal(30, 1, 10)),
        }
    )
    tests = pairwise_tests(table)
    study = tests[tests.family == "study"]
    baseline = tests[tests.family == "baseline"]
    assert len(study) == 3 and len(baseline) == 3
    assert (baseline.approach_b == "RANDOM").all()
    without = pairwise_tests(table[table.approach != "RANDOM"])
    np.testing.assert_allclose(study.p_holm.to_numpy(), without.p_holm.to_numpy())
    assert set(tests.method) == {"exact"}


def test_header_names_the_budget_and_warns_about_small_budgets_and_thin_cells():
    table = trials({("EA", "Fp"): [1.0, 2.0, 3.0], ("MAP-LIS", "Fp"): [1.0] * 6})
    config = {
        "evaluations": 1500,
        "batch_size": 500,
        "mode": "legacy",
        "target": "D16",
        "trials": 6,
        "approaches": ["EA", "MAP-LIS"],
        "fitnesses": ["Fp"],
    }
    said, warnings = context(config, summary_table(table))
    assert "1,500 evaluations" in said and "mode legacy" in said and "6 trials" in said
    assert any("below the study's 726,750" in w for w in warnings)
    assert any("EA/Fp (3)" in w and "MAP-LIS" not in w for w in warnings)
    said, warnings = context({**config, "evaluations": 726_750}, summary_table(table))
    assert not any("below" in w for w in warnings)


@pytest.mark.parametrize("approach", ["EA", "MAP-AU"])
def test_summary_counts_every_finished_trial(approach):
    table = trials({(approach, "Fsl"): [-3.0, -1.0, -2.0]})
    row = summary_table(table).iloc[0]
    assert (row.n_finished, row["median"], row["min"]) == (3, -2.0, -3.0)


def test_a12_interval_brackets_the_estimate_and_is_reproducible():
    rng = np.random.default_rng(3)
    x, y = rng.normal(0.0, 1.0, 10), rng.normal(1.0, 1.0, 10)
    low, high = a12_interval(x, y)
    assert low <= a12(x, y) <= high and high - low > 0.1
    assert a12_interval(x, y) == (low, high)  # seeded
    assert a12_interval(np.zeros(10), np.ones(10)) == (0.0, 0.0)  # no overlap: A12 is 0


def test_one_rule_judges_every_claim():
    def row(a12, low, high, p):
        return pd.Series({"a12": a12, "a12_low": low, "a12_high": high, "p_holm": p})

    assert judge(row(0.10, 0.02, 0.30, 0.01)) == REPRODUCED
    assert judge(row(0.10, 0.02, 0.30, 0.20)) == DIRECTION_ONLY  # not significant
    assert judge(row(0.40, 0.15, 0.65, 0.04)) == DIRECTION_ONLY  # interval holds 0.5
    assert judge(row(0.60, 0.35, 0.85, 0.50)) == NOT_REPRODUCED
    assert judge(row(0.90, 0.75, 1.00, 0.01)) == CONTRADICTED
    assert judge(row(0.90, 0.75, 1.00, 0.01), lower=False) == REPRODUCED
    # an interval that only touches 0.5 does not exclude it: the reverse is not shown
    assert judge(row(0.80, 0.50, 1.00, 0.01)) == NOT_REPRODUCED
    assert judge(row(0.20, 0.00, 0.50, 0.01), lower=False) == NOT_REPRODUCED
    assert similar(row(0.50, 0.35, 0.66, 0.90)) == REPRODUCED
    assert similar(row(0.50, 0.20, 0.80, 0.90)) == NOT_SHOWN  # too wide to say
    assert similar(row(0.05, 0.00, 0.15, 0.01)) == NOT_REPRODUCED
    assert weakest([REPRODUCED, DIRECTION_ONLY, REPRODUCED]) == DIRECTION_ONLY
    assert weakest([REPRODUCED, CONTRADICTED, NOT_REPRODUCED]) == CONTRADICTED


def test_the_rules_power_grows_with_trials_and_effect_and_is_alpha_without_one():
    from linkevo.orchestrator.report.stats import rule_power

    assert rule_power(30, 1, 0.5, draws=4000) == pytest.approx(0.05, abs=0.015)
    assert rule_power(10, 15, 0.71) < rule_power(30, 15, 0.71) < rule_power(30, 1, 0.71)
    assert rule_power(30, 15, 0.9) > 0.95


def test_thousands_ticks_never_repeat():
    from matplotlib.figure import Figure

    from linkevo.orchestrator.report.figures import thousands

    ax = Figure().add_subplot()
    ax.set_xlim(0, 2000)
    ax.set_xticks([0, 500, 1000, 1500, 2000])
    thousands(ax)
    ax.figure.canvas.draw()
    labels = [t.get_text() for t in ax.get_xticklabels()]
    assert labels == ["0", "0.5k", "1k", "1.5k", "2k"]


def test_claim_12_sees_a_peaked_dependence_that_spearman_misses():
    """A loss that is best at one path size (a peak) has no monotone trend: Spearman's rho
    is near 0, Chatterjee's xi near 1, and claim 12 reads high on the stronger of the two."""
    from linkevo.orchestrator.report.findings import (
        HIGH_DEPENDENCE,
        _highly_correlated,
    )
    from linkevo.orchestrator.report.measures import (
        descriptor_correlation,
        descriptor_dependence,
    )

    rng = np.random.default_rng(0)
    archives = []
    for _ in range(10):
        width = rng.uniform(0, 1, 400)
        archives.append(
            pd.DataFrame({"loss": (width - 0.5) ** 2, "desc_0": width, "desc_1": rng.random(400)})
        )
    rho = [descriptor_correlation(a) for a in archives]
    xi = [descriptor_dependence(a) for a in archives]
    assert max(rho) < 0.2 and min(xi) > 0.9 > HIGH_DEPENDENCE
    trials = pd.DataFrame(
        {
            "approach": "MAP-WH",
            "fitness": "Fp",
            "descriptor_correlation": rho,
            "descriptor_dependence": xi,
        }
    )
    peaked = _highly_correlated(trials, "Fp")
    assert peaked.verdict == "reproduced" and "median xi" in peaked.evidence
    rho_only = _highly_correlated(trials.drop(columns="descriptor_dependence"), "Fp")
    assert rho_only.verdict == "contradicted"
    assert "xi not measured" in rho_only.evidence
    assert pytest.approx(0.30, abs=0.01) == HIGH_DEPENDENCE
