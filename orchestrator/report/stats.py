"""Provides the report's statistics: per-cell summaries, Mann–Whitney U, Holm, A12."""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pandas as pd
from scipy.stats import bootstrap, mannwhitneyu

from linkevo.sim.study import APPROACHES, BASELINE, FITNESSES, ordered

ALPHA = 0.05
"""Family-wise significance level of the Holm-corrected tests (per fitness)."""
A12_THRESHOLDS: tuple[tuple[float, str], ...] = (
    (0.56, "negligible"),
    (0.64, "small"),
    (0.71, "medium"),
)
"""Vargha and Delaney's (2000) bounds on max(A12, 1 - A12); above the last: large."""


def a12(x: np.ndarray, y: np.ndarray) -> float:
    """Returns Vargha–Delaney A12 = P(X > Y) + P(X = Y) / 2 for samples x (n,), y (m,).

    For losses, A12 < 0.5 means x tends to be lower (better) than y.
    """
    x = np.asarray(x, dtype=float)[:, None]
    y = np.asarray(y, dtype=float)[None, :]
    return float(((x > y).sum() + 0.5 * (x == y).sum()) / (x.size * y.size))


BOOTSTRAP_RESAMPLES = 9999
CONFIDENCE = 0.95


def _a12_along(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
    """A12 of x over y along the last axis, batched over the leading ones (for scipy)."""
    x = np.moveaxis(np.asarray(x, dtype=float), axis, -1)[..., :, None]
    y = np.moveaxis(np.asarray(y, dtype=float), axis, -1)[..., None, :]
    wins = (x > y).sum(axis=(-2, -1)) + 0.5 * (x == y).sum(axis=(-2, -1))
    return wins / (x.shape[-2] * y.shape[-1])


def a12_interval(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Returns the 95 % bootstrap interval of A12 of x (n,) over y (m,).

    scipy's `bootstrap`, resampling each sample on its own, 9,999 resamples, seeded (a
    report is reproducible). Percentile intervals: BCa fails exactly where the samples do
    not overlap (A12 0 or 1), which is common here. NaN for a sample of fewer than two.
    """
    return _interval(_a12_along, x, y)


def median_interval(x: np.ndarray) -> tuple[float, float]:
    """Returns the 95 % bootstrap interval of the median of x (n,), as `a12_interval`
    computes its own (percentile, 9,999 resamples, seeded); NaN for fewer than two."""
    return _interval(np.median, x)


def _interval(statistic, *samples: np.ndarray) -> tuple[float, float]:
    """The 95 % percentile bootstrap interval of a vectorised statistic of the samples,
    each resampled on its own, seeded; NaN when a sample has fewer than two values."""
    if min(np.size(s) for s in samples) < 2:
        return np.nan, np.nan
    result = bootstrap(
        tuple(np.asarray(s, dtype=float) for s in samples),
        statistic,
        n_resamples=BOOTSTRAP_RESAMPLES,
        confidence_level=CONFIDENCE,
        method="percentile",
        vectorized=True,
        rng=np.random.default_rng(0),
    )
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def a12_magnitude(value: float) -> str:
    """Returns the effect-size label of an A12 value (negligible, small, medium, large)."""
    distance = max(value, 1.0 - value)
    for bound, label in A12_THRESHOLDS:
        if distance < bound:
            return label
    return "large"


def rule_power(n: int, pairs: int, true_a12: float, draws: int = 2000, seed: int = 0) -> float:
    """Returns how often the rule's test finds a real difference of `true_a12` between two
    samples of `n` trials, the most significant pair of a family of `pairs` (Holm's first
    threshold, ALPHA / pairs): by simulation, normal samples shifted so that A12 is
    `true_a12`, `draws` times."""
    from scipy.stats import norm

    rng = np.random.default_rng(seed)
    shift = np.sqrt(2.0) * norm.ppf(true_a12)
    x = rng.normal(size=(draws, n))
    y = rng.normal(size=(draws, n)) + shift
    method = "exact" if n <= 8 else "asymptotic"
    p = mannwhitneyu(x, y, axis=1, alternative="two-sided", method=method).pvalue
    return float(np.mean(p < ALPHA / pairs))


def holm(pvalues: np.ndarray) -> np.ndarray:
    """Returns Holm–Bonferroni adjusted p-values (m,) for raw p-values (m,), same order."""
    p = np.asarray(pvalues, dtype=float)
    m = p.size
    order = np.argsort(p, kind="stable")
    scaled = np.minimum(1.0, (m - np.arange(m)) * p[order])
    adjusted = np.empty(m)
    adjusted[order] = np.maximum.accumulate(scaled)
    return adjusted


def summary_table(trials: pd.DataFrame) -> pd.DataFrame:
    """Returns one row per approach × fitness: trial counts and best-loss quartiles.

    Args:
        trials: `GridData.trials` (columns approach, fitness, status, best_loss).

    Returns:
        Columns fitness, approach, n_finished, n_failed (FAILED), n_incomplete (KILLED or
        RUNNING), n_missing, median, q1, q3, iqr, min, max; quartiles over the FINISHED
        trials' best losses (NaN when none finished).
    """
    rows = []
    for fitness in ordered(trials.fitness.unique(), FITNESSES):
        for approach in ordered(trials.approach.unique(), APPROACHES):
            cell = trials[(trials.approach == approach) & (trials.fitness == fitness)]
            if cell.empty:
                continue
            losses = cell.best_loss[(cell.status == "FINISHED") & cell.best_loss.notna()]
            q1, median, q3 = (
                np.quantile(losses, [0.25, 0.5, 0.75]) if len(losses) else (np.nan,) * 3
            )
            rows.append(
                {
                    "fitness": fitness,
                    "approach": approach,
                    "n_finished": len(losses),
                    "n_failed": int((cell.status == "FAILED").sum()),
                    "n_incomplete": int(cell.status.isin(["KILLED", "RUNNING"]).sum()),
                    "n_missing": int((cell.status == "MISSING").sum()),
                    "median": median,
                    "q1": q1,
                    "q3": q3,
                    "iqr": q3 - q1,
                    "min": losses.min() if len(losses) else np.nan,
                    "max": losses.max() if len(losses) else np.nan,
                }
            )
    return pd.DataFrame(rows)


def mann_whitney(x: np.ndarray, y: np.ndarray) -> tuple[float, float, str]:
    """Returns the two-sided Mann–Whitney U of x over y, its p-value and the method:
    "exact" where the pooled sample has no ties (scipy's exact null distribution), else
    "asymptotic" (normal approximation with tie and continuity corrections)."""
    pooled = np.concatenate([x, y])
    method = "exact" if np.unique(pooled).size == pooled.size else "asymptotic"
    test = mannwhitneyu(x, y, alternative="two-sided", method=method)
    return float(test.statistic), float(test.pvalue), method


TEST_COLUMNS: tuple[str, ...] = (
    "fitness",
    "family",
    "approach_a",
    "approach_b",
    "n_a",
    "n_b",
    "median_a",
    "median_b",
    "u",
    "method",
    "p",
    "p_holm",
    "significant",
    "a12",
    "a12_low",
    "a12_high",
    "magnitude",
    "better",
)
"""The columns of `pairwise_tests`."""


def pairwise_tests(
    trials: pd.DataFrame, measure: str = "best_loss", higher_is_better: bool = False
) -> pd.DataFrame:
    """Returns two-sided Mann–Whitney U tests of a per-trial measure (default: the best
    loss) between approaches, per fitness.

    Two families per fitness, each Holm-corrected on its own: "study" (pairs of the
    study's approaches) and "baseline" (each approach against RANDOM), so adding the
    baseline leaves the study's comparisons as they would be without it. Pairs where
    either side has no finished trial are left out.

    Returns:
        `TEST_COLUMNS`: fitness, family, approach_a, approach_b, n_a, n_b, median_a,
        median_b, u (U of a), method ("exact" or "asymptotic", see `mann_whitney`), p,
        p_holm, significant (p_holm < ALPHA), a12 (A12 of a over b), a12_low and a12_high
        (its 95 % bootstrap interval, `a12_interval`), magnitude, better
        (the approach with the better median, lower unless `higher_is_better`, where the
        difference is significant, else "").
    """
    done = trials[(trials.status == "FINISHED") & trials[measure].notna()]
    frames = []
    for fitness in ordered(done.fitness.unique(), FITNESSES):
        groups = {
            a: done[measure][(done.fitness == fitness) & (done.approach == a)].to_numpy()
            for a in ordered(done.approach[done.fitness == fitness].unique(), APPROACHES)
        }
        rows = []
        for a, b in combinations(groups, 2):
            x, y = groups[a], groups[b]
            u, p, method = mann_whitney(x, y)
            effect = a12(x, y)
            low, high = a12_interval(x, y)
            med_a, med_b = float(np.median(x)), float(np.median(y))
            rows.append(
                {
                    "fitness": fitness,
                    "family": "baseline" if BASELINE in (a, b) else "study",
                    "approach_a": a,
                    "approach_b": b,
                    "n_a": x.size,
                    "n_b": y.size,
                    "median_a": med_a,
                    "median_b": med_b,
                    "u": u,
                    "method": method,
                    "p": p,
                    "a12": effect,
                    "a12_low": low,
                    "a12_high": high,
                    "magnitude": a12_magnitude(effect),
                    "better": ""
                    if med_a == med_b
                    else a
                    if (med_a < med_b) != higher_is_better
                    else b,
                }
            )
        for family in ("study", "baseline"):
            frame = pd.DataFrame([r for r in rows if r["family"] == family])
            if frame.empty:
                continue
            frame["p_holm"] = holm(frame.p.to_numpy())
            frame["significant"] = frame.p_holm < ALPHA
            frame["better"] = frame.better.where(frame.significant, "")
            frames.append(frame[list(TEST_COLUMNS)])
    if not frames:
        return pd.DataFrame(columns=list(TEST_COLUMNS))
    return pd.concat(frames, ignore_index=True)
