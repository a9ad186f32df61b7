"""Provides PublishedGrid: pyribs' GridArchive with the study's binning."""

from __future__ import annotations

import numpy as np
from ribs.archives import GridArchive

from linkevo.sim.linkage.descriptors import DescriptorSpace, bin_descriptors, cell_index


class PublishedGrid(GridArchive):
    """A pyribs `GridArchive` whose cells are the study's bins (`sim.linkage.descriptors`).

    pyribs bins a value v of a dimension with R cells over [lo, hi] as
    floor(R (v - lo) / (hi - lo) + eps); the study bins it as #{i in 1..R-1 : v > i*step},
    which differs on every bin edge. Only `index_of` is replaced; insertion, thresholds and
    storage are pyribs'. The archive maximises, so the objective is the negated loss.

    Args:
        space: the descriptor space and its published binning.
        sigma_width: S, mutation strengths per genome (1 paper, 2 legacy).
        path_length: A, crank angles of a stored foot path.
    """

    def __init__(self, *, space: DescriptorSpace, sigma_width: int, path_length: int) -> None:
        super().__init__(
            solution_dim=56,
            dims=space.shape,
            ranges=[(0.0, step * space.resolution) for step in space.step],
            dtype=np.float64,
            extra_fields={
                "sigma": ((sigma_width,), np.float64),
                "error": ((), np.int64),
                "angle_error": ((), np.float64),
                "foot_x": ((path_length,), np.float64),
                "foot_y": ((path_length,), np.float64),
            },
        )
        self.space = space

    def index_of(self, measures: np.ndarray) -> np.ndarray:
        """Returns the flat published cell of descriptors (N, D) -> (N,) int64."""
        return cell_index(bin_descriptors(measures, self.space), self.space)

    def at(self, cells: np.ndarray, names: list[str]) -> dict[str, np.ndarray]:
        """Returns the named fields of the elites in `cells`, (K,) -> {name: (K, ...)}.

        pyribs reads whole archives in its own storage order (`data`); reading given
        cells straight from the store spares the trial a copy and a sort per iteration.
        """
        return self._store.retrieve(cells, names, return_type="dict")[1]
