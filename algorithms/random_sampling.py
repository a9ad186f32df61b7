"""Provides RandomSampling: the uniform random baseline (RANDOM) on a MAP-Elites grid."""

from __future__ import annotations

import numpy as np

from linkevo.algorithms.map_elites import MapElites
from linkevo.sim.linkage.descriptors import COVERAGE_SPACES, DESCRIPTOR_SPACES
from linkevo.sim.linkage.evaluation import Evaluation


class RandomSampling(MapElites):
    """Every batch is uniform random genomes; all of them are kept in an archive on the
    `coverage_space` grid (MAP-LIS by default), so coverage, QD-score and the best loss
    are those of random search at the same budget, measured as MAP-Elites' are.

    A QD comparison needs it to say whether the search helps at all: a grid that random
    sampling fills as well as MAP-Elites does says nothing about the search.

    Args:
        coverage_space: the grid the samples are kept on ("MAP-WH", "MAP-LIS", "MAP-ST").
        **kwargs: as `BaseOptimizer`.
    """

    random_batches = True

    def __init__(self, *, coverage_space: str = "MAP-LIS", **kwargs: object) -> None:
        if coverage_space not in COVERAGE_SPACES:
            raise ValueError(
                f"unknown coverage_space {coverage_space!r}; allowed: {', '.join(COVERAGE_SPACES)}"
            )
        super().__init__(approach="RANDOM", space=DESCRIPTOR_SPACES[coverage_space], **kwargs)
        self.coverage_space = coverage_space

    def descriptors_of(self, genomes: np.ndarray, evaluation: Evaluation) -> np.ndarray:
        """Returns the coverage space's descriptors (B, D) from the evaluation."""
        return evaluation.descriptors[self.coverage_space]

    def settings(self) -> dict[str, object]:
        """Returns the JSON-able settings, with the coverage space."""
        return super().settings() | {"coverage_space": self.coverage_space}
