"""Provides the standard generational EA with tournament selection (spec §6)."""

from __future__ import annotations

import numpy as np

from linkevo.algorithms.individuals import Individuals
from linkevo.algorithms.population import PopulationOptimizer
from linkevo.algorithms.selection import tournament

TOURNAMENT_SIZE = 3


class EvolutionaryAlgorithm(PopulationOptimizer):
    """Each iteration: B tournament winners (size 3) are mutated; the children replace them.

    Args:
        **kwargs: as `PopulationOptimizer`.
    """

    approach = "EA"

    def _parents(self) -> tuple[np.ndarray, np.ndarray]:
        pop = self._population
        assert pop is not None
        winners = tournament(self._scalar(pop), self.batch_size, self._rng, TOURNAMENT_SIZE)
        return pop.genome[winners], pop.sigma[winners]

    def _survive(self, batch: Individuals, *, initial: bool) -> None:
        self._population = batch
