"""Provides `compare_grids`: two grids' best losses side by side, cell by cell."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.orchestrator.report.load import load_grid
from linkevo.orchestrator.report.stats import ALPHA, a12, holm, mann_whitney
from linkevo.sim.study import APPROACHES, FITNESSES, ordered

COLUMNS: tuple[str, ...] = (
    "fitness", "approach", "n_a", "median_a", "n_b", "median_b", "difference",
    "u", "method", "p", "p_holm", "significant", "a12",
)  # fmt: skip
"""The columns of `compare_grids`."""


def compare_grids(
    tracking_uri: str, grid_a: str, grid_b: str, experiment: str = "linkevo"
) -> pd.DataFrame:
    """Returns one row per (fitness, approach) the two grids share: each grid's finished
    trials and median best loss, the difference (b - a), and a two-sided Mann–Whitney U
    of a against b (`stats.mann_whitney`), Holm-corrected over the approaches of one
    fitness; A12 < 0.5 means grid a's losses tend to be lower.

    Raises:
        GridNotFoundError: when either grid is not in the store.
    """
    with tempfile.TemporaryDirectory(prefix="linkevo-compare-") as cache:
        done = [
            load_grid(tracking_uri, grid, Path(cache) / grid, experiment).finished()
            for grid in (grid_a, grid_b)
        ]
    rows = []
    for fitness in ordered(set(done[0].fitness) & set(done[1].fitness), FITNESSES):
        shared = set(done[0].approach[done[0].fitness == fitness])
        shared &= set(done[1].approach[done[1].fitness == fitness])
        for approach in ordered(shared, APPROACHES):
            x, y = (
                d.best_loss[(d.fitness == fitness) & (d.approach == approach)].to_numpy()
                for d in done
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
