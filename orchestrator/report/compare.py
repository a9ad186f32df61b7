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
    "fitness", "approach", "n_a", "median_a", "n_b", "median_b", "difference",
    "u", "method", "p", "p_holm", "significant", "a12",
)  # fmt: skip
"""The columns of `compare_grids`."""


def compare_grids(
    tracking_uri: str | None, grid_a: str, grid_b: str, experiment: str = "linkevo"
) -> pd.DataFrame:
    """Returns `compare_trials` of two grids, each a grid id in the store or the path of a
    report's `trials.csv` (a published grid compares without its store).

    Raises:
        NotFound: when a grid is not in the store.
        TrialsTableError: when a trials table lacks the columns a report writes.
    """
    with tempfile.TemporaryDirectory(prefix="linkevo-compare-") as cache:
        a, b = (
            finished_trials(read_trials_csv(grid))
            if is_trials_csv(grid)
            else load_grid(tracking_uri, grid, Path(cache) / grid, experiment).finished()
            for grid in (grid_a, grid_b)
        )
    return compare_trials(a, b)


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
