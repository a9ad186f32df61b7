"""Provides PopulationOptimizer: the shared base of the fixed-size population searches."""

from __future__ import annotations

import numpy as np

from linkevo.algorithms import scoring
from linkevo.algorithms.archive import elite_rows
from linkevo.algorithms.individuals import Individuals
from linkevo.algorithms.optimizer import BaseOptimizer
from linkevo.sim.linkage.descriptors import (
    DESCRIPTOR_SPACES,
    bin_descriptors,
    cell_index,
    check_coverage_space,
)
from linkevo.sim.linkage.evaluation import Evaluation


class PopulationOptimizer(BaseOptimizer):
    """A search that keeps a population of B individuals (the EA and NSGA-II).

    Coverage and QD-score are measured by projecting the population onto a MAP-Elites grid
    (`coverage_space`, MAP-LIS by default): the filled fraction of its cells and the sum
    over filled cells of max(offset - best loss in the cell, 0), as an archive of the
    population would score.

    Args:
        coverage_space: the approach whose grid measures coverage ("MAP-WH", "MAP-LIS",
            "MAP-ST").
        **kwargs: as `BaseOptimizer`.
    """

    def __init__(self, *, coverage_space: str = "MAP-LIS", **kwargs: object) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        check_coverage_space(coverage_space)
        self.coverage_space = coverage_space
        self._population: Individuals | None = None

    @property
    def population(self) -> Individuals | None:
        """The current population (B rows), or None before the first tell."""
        return self._population

    def descriptors_of(self, genomes: np.ndarray, evaluation: Evaluation) -> np.ndarray:
        """Returns the coverage space's continuous descriptors (B, D) from the evaluation."""
        return evaluation.descriptors[self.coverage_space]

    def settings(self) -> dict[str, object]:
        """Returns the JSON-able settings, with the coverage space."""
        return super().settings() | {"coverage_space": self.coverage_space}

    def _kept(self) -> Individuals | None:
        return self._population

    def _summary(self) -> dict[str, float]:
        pop = self._population
        if pop is None:
            return {"mean_loss": np.nan, "coverage": 0.0, "qd_score": 0.0, **self._walkers([])}
        loss = self._scalar(pop)
        space = DESCRIPTOR_SPACES[self.coverage_space]
        cells = cell_index(bin_descriptors(pop.desc, space), space)
        best = loss[elite_rows(cells, loss)]
        return {
            "mean_loss": float(np.mean(loss)),
            "coverage": scoring.coverage(best.size, space.n_cells),
            "qd_score": scoring.qd_score(best, self.qd_offset),
            **self._walkers(best),
        }

    def _state(self) -> dict[str, np.ndarray]:
        return {} if self._population is None else self._population.to_state("population")

    def _load_state(self, state: dict[str, np.ndarray]) -> None:
        has = "population.genome" in state
        self._population = Individuals.from_state(state, "population") if has else None
