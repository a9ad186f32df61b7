"""Provides GridArchive: a vectorised MAP-Elites grid that keeps the lowest loss per cell."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np

from algorithms import scoring
from algorithms.individuals import Individuals
from sim.descriptors import DescriptorSpace, bin_descriptors, cell_index


def elite_rows(cells: np.ndarray, loss: np.ndarray) -> np.ndarray:
    """Returns the row of the lowest finite loss in every cell, in ascending cell order.

    Ties go to the earlier row.

    Args:
        cells: (N,) int64 cell index per row.
        loss: (N,) float64 losses.

    Returns:
        (K,) int64 row indices, one per distinct cell among rows with a finite loss.
    """
    finite = np.flatnonzero(np.isfinite(loss))
    order = finite[np.lexsort((finite, loss[finite], cells[finite]))]
    first = np.ones(order.shape[0], dtype=bool)
    first[1:] = cells[order[1:]] != cells[order[:-1]]
    return order[first]


class GridArchive:
    """A grid over a descriptor space holding at most one elite (the lowest loss) per cell.

    Storage is dense: one row per cell (`data`), with an occupancy mask, so an insertion
    costs O(batch), not O(archive). Per batch, the best child of each cell is found with one
    `np.lexsort` (ties: the earlier child) and written where the cell is empty or the child's
    loss is strictly lower (ties keep the incumbent). So an empty cell takes a child, a
    better child replaces the elite, and of two children for one cell in one batch the
    better survives. Rows with a non-finite loss are refused.

    Args:
        space: the descriptor space (names, resolution, step) and its published binning.
    """

    def __init__(self, *, space: DescriptorSpace) -> None:
        self._space = space
        self._occupied = np.zeros(space.n_cells, dtype=bool)
        self._data: Individuals | None = None

    @property
    def space(self) -> DescriptorSpace:
        """The descriptor space."""
        return self._space

    @property
    def n_cells(self) -> int:
        """Number of cells in the grid."""
        return self._space.n_cells

    @property
    def data(self) -> Individuals | None:
        """The dense storage, one row per cell (rows of empty cells are meaningless)."""
        return self._data

    @property
    def cells(self) -> np.ndarray:
        """(K,) int64 index of every filled cell, ascending."""
        return np.flatnonzero(self._occupied)

    @property
    def elites(self) -> Individuals | None:
        """The elites (K rows, in `cells` order), or None while the archive is empty."""
        if self._data is None or not self._occupied.any():
            return None
        return self._data.take(self.cells)

    def __len__(self) -> int:
        return int(np.count_nonzero(self._occupied))

    def bins(self, desc: np.ndarray) -> np.ndarray:
        """Returns the published bins of continuous descriptors, (N, D) -> (N, D) int64."""
        return bin_descriptors(desc, self._space)

    def cell_index(self, desc: np.ndarray) -> np.ndarray:
        """Returns the flat cell index of continuous descriptors, (N, D) -> (N,) int64."""
        return cell_index(self.bins(desc), self._space)

    def add(self, batch: Individuals) -> int:
        """Inserts a batch; returns how many of its rows became elites.

        Args:
            batch: N candidates with (N,) losses and (N, D) descriptors.
        """
        cells = self.cell_index(batch.desc)
        rows = elite_rows(cells, batch.loss)
        cells = cells[rows]
        if self._data is None:
            self._data = _allocate(batch, self.n_cells)
        wins = ~self._occupied[cells] | (batch.loss[rows] < self._data.loss[cells])
        self._write(cells[wins], batch, rows[wins])
        return int(np.count_nonzero(wins))

    def reindex(self, desc: np.ndarray) -> int:
        """Re-inserts every elite under new descriptors; returns how many were dropped.

        Elites that now share a cell keep the lowest loss (ties: the elite of the lower
        old cell).

        Args:
            desc: (K, D) new descriptors of the current elites, in `elites` order.
        """
        elites = self.elites
        if elites is None:
            return 0
        if desc.shape[0] != len(elites):
            raise ValueError(f"reindex needs {len(elites)} descriptor rows, got {desc.shape[0]}")
        moved = replace(elites, desc=np.asarray(desc, dtype=np.float64))
        cells = self.cell_index(moved.desc)
        rows = elite_rows(cells, moved.loss)
        self._occupied[:] = False
        self._write(cells[rows], moved, rows)
        return len(elites) - len(rows)

    def _write(self, cells: np.ndarray, source: Individuals, rows: np.ndarray) -> None:
        assert self._data is not None
        for f in fields(Individuals):
            getattr(self._data, f.name)[cells] = getattr(source, f.name)[rows]
        self._occupied[cells] = True

    def losses(self) -> np.ndarray:
        """Returns the (K,) losses of the elites, in `cells` order (no copy of the rest)."""
        if self._data is None:
            return np.zeros(0)
        return self._data.loss[self._occupied]

    def coverage(self) -> float:
        """Returns the filled fraction of the grid."""
        return scoring.coverage(len(self), self.n_cells)

    def qd_score(self, offset: float) -> float:
        """Returns the sum over filled cells of max(offset - loss, 0)."""
        return scoring.qd_score(self.losses(), offset)

    def state_dict(self) -> dict[str, np.ndarray]:
        """Returns the filled cells and their elites as npz-safe arrays."""
        state = {"archive.cells": self.cells}
        elites = self.elites
        if elites is not None:
            state |= elites.to_state("archive")
        return state

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restores the contents saved by `state_dict`."""
        cells = np.asarray(state["archive.cells"], dtype=np.int64)
        self._occupied[:] = False
        self._data = None
        if cells.size:
            elites = Individuals.from_state(state, "archive")
            self._data = _allocate(elites, self.n_cells)
            self._write(cells, elites, np.arange(cells.size))


def _allocate(like: Individuals, n: int) -> Individuals:
    return Individuals(
        **{
            f.name: np.zeros((n, *getattr(like, f.name).shape[1:]), getattr(like, f.name).dtype)
            for f in fields(Individuals)
        }
    )
