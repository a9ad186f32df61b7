"""Provides CommonGrid: every evaluated genome binned into one grid that all approaches
share, so coverage and QD-score compare across approaches."""

from __future__ import annotations

import numpy as np

from linkevo.algorithms import scoring
from linkevo.sim.linkage.descriptors import DESCRIPTOR_SPACES, bin_descriptors, cell_index

COMMON_SPACE = "MAP-LIS"
"""The shared grid: MAP-LIS's (mean beam length x lift, 100 x 100), whose descriptors
`sim.linkage.evaluating` computes for every genome, whatever the approach."""


class CommonGrid:
    """A passive archive (pyribs' "result archive" practice): the lowest loss ever told in
    each cell of the MAP-LIS grid, from every evaluated genome with a finite loss, whether
    or not the search kept it. Its coverage and QD-score are cumulative for every approach
    (the EA's and NSGA-II's own figures are their current population's); for MAP-LIS it
    equals the repertoire's own.

    It keeps only the (cells,) best losses, not the genomes, so its whole state is one
    array in the checkpoint; a pyribs archive would store a solution per cell.
    """

    def __init__(self) -> None:
        self._space = DESCRIPTOR_SPACES[COMMON_SPACE]
        self._best = np.full(self._space.n_cells, np.nan)

    def add(self, desc: np.ndarray, loss: np.ndarray) -> None:
        """Takes a batch's MAP-LIS descriptors (B, 2) and single-objective losses (B,)."""
        keep = np.isfinite(loss) & np.isfinite(desc).all(axis=1)
        cells = cell_index(bin_descriptors(desc[keep], self._space), self._space)
        np.fmin.at(self._best, cells, loss[keep])

    def incumbents(self, desc: np.ndarray) -> np.ndarray:
        """Returns (N,) the best loss told in the cell of each MAP-LIS descriptor row
        (N, 2), inf where none (or where a row has no cell)."""
        out = np.full(len(desc), np.inf)
        keep = np.isfinite(desc).all(axis=1)
        cells = cell_index(bin_descriptors(desc[keep], self._space), self._space)
        out[keep] = np.nan_to_num(self._best[cells], nan=np.inf)
        return out

    def coverage(self) -> float:
        """Returns the filled fraction of the grid."""
        return scoring.coverage(int(np.isfinite(self._best).sum()), self._space.n_cells)

    def qd_score(self, offset: float) -> float:
        """Returns the sum over filled cells of max(offset - best loss, 0)."""
        return scoring.qd_score(self._best[np.isfinite(self._best)], offset)

    def state_dict(self) -> dict[str, np.ndarray]:
        """Returns {"common.best": (cells,) float64, NaN where empty}."""
        return {"common.best": self._best.copy()}

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restores `state_dict`'s output."""
        best = np.asarray(state["common.best"], dtype=np.float64)
        if best.shape != self._best.shape:
            raise ValueError(f"common grid state: expected {self._best.shape}, got {best.shape}")
        self._best = best.copy()
