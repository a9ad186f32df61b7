"""Provides `compare_grids` and `compare_trials`: two grids' best losses side by side, cell
by cell, from a store or from reports' `trials.csv`."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.orchestrator.report.load import finished_trials, load_grid
from linkevo.orchestrator.report.stats import ALPHA, a12, holm, mann_whitney
from linkevo.sim.errors import LinkevoError
from linkevo.sim.study import APPROACHES, FITNESSES, ordered

COLUMNS: tuple[str, ...] = (
    "fitness",
    "approach",
    "n_a",
    "median_a",
    "n_b",
    "median_b",
    "difference",
    "u",
    "method",
    "p",
    "p_holm",
    "significant",
    "a12",
)
"""The columns of `compare_grids`."""


def compare_grids(
    tracking_uri: str | None, grid_a: str, grid_b: str, experiment: str = "linkevo"
) -> tuple[pd.DataFrame, list[str]]:
    """Returns `compare_trials` of two grids, each a grid id in the store or the path of a
    report's `trials.csv` (a published grid compares without its store), and the
    `differences` that make the comparison unlike for like.

    Raises:
        NotFound: when a grid is not in the store.
        TrialsTableError: when a trials table lacks the columns a report writes.
    """
    sides = []
    with tempfile.TemporaryDirectory(prefix="linkevo-compare-") as cache:
        for grid in (grid_a, grid_b):
            if is_trials_csv(grid):
                sides.append((finished_trials(read_trials_csv(grid)), None))
            else:
                data = load_grid(tracking_uri, grid, Path(cache) / grid, experiment)
                sides.append((data.finished(), data.config.get("mode")))
    (a, mode_a), (b, mode_b) = sides
    table = compare_trials(a, b)
    return table, differences(a, b, table, mode_a, mode_b)


def differences(
    a: pd.DataFrame, b: pd.DataFrame, table: pd.DataFrame, mode_a: str | None, mode_b: str | None
) -> list[str]:
    """Returns a warning per way the two grids' compared cells differ in what they ran:
    the mode (when both are known: a trials.csv does not say), the budget (the median of
    `final_evaluations` per approach and fitness, where both tables have it) and the
    trials per cell."""
    out = []
    if mode_a and mode_b and mode_a != mode_b:
        out.append(f"the grids ran in different modes: a {mode_a}, b {mode_b}")
    for row in table.itertuples():
        cell = f"{row.approach} {row.fitness}"
        if row.n_a != row.n_b:
            out.append(f"{cell}: {row.n_a} trials in a, {row.n_b} in b")
        if "final_evaluations" in a and "final_evaluations" in b:
            budgets = [
                float(
                    np.median(
                        d.final_evaluations[
                            (d.fitness == row.fitness) & (d.approach == row.approach)
                        ]
                    )
                )
                for d in (a, b)
            ]
            if budgets[0] != budgets[1] and not np.isnan(budgets).any():
                out.append(
                    f"{cell}: a budget of {budgets[0]:,.0f} evaluations in a, "
                    f"{budgets[1]:,.0f} in b"
                )
    return out


def is_trials_csv(grid: str) -> bool:
    """True when a grid argument names a report's trials table rather than a grid id."""
    return grid.endswith(".csv")


class TrialsTableError(LinkevoError, ValueError):
    """A trials table that is not one a report writes."""


def read_trials_csv(path: str) -> pd.DataFrame:
    """Returns a report's trials table.

    Raises:
        TrialsTableError: naming the file, when it is not a table or lacks a column.
    """
    try:
        trials = pd.read_csv(path)
    except (OSError, ValueError) as exc:
        problem = f"trials table {path!r} is not a readable CSV table ({exc})"
        raise TrialsTableError(problem) from exc
    missing = [c for c in ("approach", "fitness", "status", "best_loss") if c not in trials]
    if missing:
        raise TrialsTableError(
            f"trials table {path!r} lacks the columns {', '.join(missing)}; allowed: the "
            "trials.csv a report writes"
        )
    return trials


def compare_trials(a: pd.DataFrame, b: pd.DataFrame) -> pd.DataFrame:
    """Returns one row per (fitness, approach) two sets of finished trials share (columns
    approach, fitness, best_loss): each one's trials and median best loss, the difference
    (b - a), and a two-sided Mann–Whitney U of a against b (`stats.mann_whitney`),
    Holm-corrected over the approaches of one fitness; A12 < 0.5 means a's losses tend to
    be lower."""
    rows = []
    for fitness in ordered(set(a.fitness) & set(b.fitness), FITNESSES):
        shared = set(a.approach[a.fitness == fitness]) & set(b.approach[b.fitness == fitness])
        for approach in ordered(shared, APPROACHES):
            x, y = (
                d.best_loss[(d.fitness == fitness) & (d.approach == approach)].to_numpy()
                for d in (a, b)
            )
            u, p, method = mann_whitney(x, y)
            rows.append(
                {
                    "fitness": fitness,
                    "approach": approach,
                    "n_a": x.size,
                    "median_a": float(np.median(x)),
                    "n_b": y.size,
                    "median_b": float(np.median(y)),
                    "difference": float(np.median(y) - np.median(x)),
                    "u": u,
                    "method": method,
                    "p": p,
                    "a12": a12(x, y),
                }
            )
    table = pd.DataFrame(rows, columns=[c for c in COLUMNS if c not in ("p_holm", "significant")])
    table["p_holm"] = np.nan
    for fitness in table.fitness.unique():
        rows_of = table.fitness == fitness
        table.loc[rows_of, "p_holm"] = holm(table.p[rows_of].to_numpy())
    table["significant"] = table.p_holm < ALPHA
    return table[list(COLUMNS)]
