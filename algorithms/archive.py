"""Provides GridArchive: the MAP-Elites repertoire, a pyribs `GridArchive` with the published
binning, holding the lowest loss per cell."""

from __future__ import annotations

from dataclasses import fields, replace
from typing import TYPE_CHECKING

import numpy as np

from linkevo.algorithms import scoring
from linkevo.algorithms.individuals import Individuals
from linkevo.sim.linkage.descriptors import DescriptorSpace, bin_descriptors, cell_index

if TYPE_CHECKING:
    from linkevo.algorithms.ribs_grid import PublishedGrid

_RIBS_NAMES = {"genome": "solution", "loss": "objective", "desc": "measures"}
"""Individuals fields that pyribs stores under its own names (the rest are extra fields)."""


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
    """The repertoire: at most one elite (the lowest loss) per cell of a descriptor grid.

    Insertion is pyribs' (`PublishedGrid.add`): a child takes its cell when the cell is
    empty or its loss is strictly lower (ties keep the incumbent), and of several children
    for one cell in one batch the best (ties: the earlier) is the candidate. Rows with a
    non-finite loss or descriptor are refused. Everything read back is in ascending cell
    order, so the same seed draws the same parents.

    Args:
        space: the descriptor space (names, resolution, step) and its published binning.
    """

    def __init__(self, *, space: DescriptorSpace) -> None:
        self._space = space
        self._grid: PublishedGrid | None = None  # made by the first add, which fixes S and A
        self._cells: np.ndarray | None = None  # `cells`, until the next insertion

    @property
    def space(self) -> DescriptorSpace:
        """The descriptor space."""
        return self._space

    @property
    def n_cells(self) -> int:
        """Number of cells in the grid."""
        return self._space.n_cells

    @property
    def cells(self) -> np.ndarray:
        """(K,) int64 index of every filled cell, ascending."""
        if self._cells is None:
            filled = self._grid.data("index") if self._grid is not None else np.zeros(0)
            self._cells = np.sort(filled).astype(np.int64)
        return self._cells

    @property
    def elites(self) -> Individuals | None:
        """The elites (K rows, in `cells` order), or None while the archive is empty."""
        if not len(self):
            return None
        return Individuals(**self.columns(*(f.name for f in fields(Individuals))))

    def columns(self, *names: str, rows: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Returns named `Individuals` fields of the elites: {name: (K, ...)} in `cells` order.

        Args:
            names: field names of `Individuals`.
            rows: (M,) positions in `cells` to read instead of all K (repeats allowed).
        """
        if self._grid is None:
            raise RuntimeError("the archive is empty")
        cells = self.cells if rows is None else self.cells[rows]
        data = self._grid.at(cells, [_RIBS_NAMES.get(n, n) for n in names])
        columns = {n: data[_RIBS_NAMES.get(n, n)] for n in names}
        if "loss" in columns:
            columns["loss"] = -columns["loss"]
        return columns

    def __len__(self) -> int:
        return 0 if self._grid is None else len(self._grid)

    def bins(self, desc: np.ndarray) -> np.ndarray:
        """Returns the published bins of continuous descriptors, (N, D) -> (N, D) int64."""
        return bin_descriptors(desc, self._space)

    def cell_index(self, desc: np.ndarray) -> np.ndarray:
        """Returns the flat cell index of continuous descriptors, (N, D) -> (N,) int64."""
        return cell_index(self.bins(desc), self._space)

    def add(self, batch: Individuals) -> int:
        """Inserts a batch; returns how many cells got a new elite.

        Args:
            batch: N candidates with (N,) losses and (N, D) descriptors.
        """
        keep = np.isfinite(batch.loss) & np.isfinite(batch.desc).all(axis=1)
        if not keep.any():
            return 0
        if self._grid is None:
            # pyribs imports torch and scikit-learn (about 3 s), so it is loaded by the first
            # insertion: the CLI, config checks and the other approaches do not pay for it.
            from linkevo.algorithms.ribs_grid import PublishedGrid

            self._grid = PublishedGrid(
                space=self._space,
                sigma_width=batch.sigma.shape[1],
                path_length=batch.foot_x.shape[1],
            )
        kept = batch if keep.all() else batch.take(np.flatnonzero(keep))
        self._cells = None
        status = self._grid.add(
            **{_RIBS_NAMES.get(f.name, f.name): getattr(kept, f.name) for f in fields(kept)}
            | {"objective": -kept.loss}
        )["status"]
        return int(np.unique(self._grid.index_of(kept.desc[status > 0])).size)

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
        assert self._grid is not None
        self._grid.clear()
        self._cells = None
        self.add(replace(elites, desc=np.asarray(desc, dtype=np.float64)))
        return len(elites) - len(self)

    def incumbents(self, desc: np.ndarray) -> np.ndarray:
        """Returns (N,) the elite's loss in the cell of each descriptor row (N, D), inf
        where the cell is empty: what a child there must beat."""
        cells, filled = self.cell_index(desc), self.cells
        if not len(filled):
            return np.full(len(cells), np.inf)
        at = np.minimum(np.searchsorted(filled, cells), len(filled) - 1)
        return np.where(filled[at] == cells, self.losses()[at], np.inf)

    def losses(self) -> np.ndarray:
        """Returns the (K,) losses of the elites, in `cells` order."""
        if not len(self):
            return np.zeros(0)
        return self.columns("loss")["loss"]

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
        """Restores the contents saved by `state_dict`.

        Raises:
            ValueError: when the saved elites do not bin to the saved cells (a state of
                another descriptor space).
        """
        cells = np.asarray(state["archive.cells"], dtype=np.int64)
        self._grid = None
        self._cells = None
        if cells.size:
            self.add(Individuals.from_state(state, "archive"))
            if not np.array_equal(self.cells, cells):
                raise ValueError(
                    f"the saved elites do not bin to their saved cells in the "
                    f"{'/'.join(self._space.names)} grid"
                )
