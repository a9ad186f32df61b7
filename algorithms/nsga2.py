"""Provides NSGA-II on the two-objective variant of the study's fitness (spec §6)."""

from __future__ import annotations

import numpy as np

from linkevo.algorithms.individuals import Individuals
from linkevo.algorithms.pareto import hypervolume_2d, select_nsga2
from linkevo.algorithms.population import PopulationOptimizer
from linkevo.algorithms.scoring import HV_REFERENCES


class NSGA2(PopulationOptimizer):
    """Each parent of the population is mutated once; NSGA-II selection of B survivors
    from parents + children (fronts by a 2-objective sweep, last front by crowding).

    The population is kept front by front. Metrics add the hypervolume of the population
    against `HV_REFERENCES[eval_fitness]`; best and mean loss are the single-objective
    losses recovered from both objectives (`scoring.scalar_loss`).

    Args:
        **kwargs: as `PopulationOptimizer`.
    """

    approach = "NSGA2"
    multi_objective = True

    def __init__(self, **kwargs: object) -> None:
        super().__init__(**kwargs)
        self.hv_reference = HV_REFERENCES[self.eval_fitness]
        self._front = np.zeros(0, dtype=np.int64)
        self._crowding = np.zeros(0)

    def _parents(self) -> tuple[np.ndarray, np.ndarray]:
        assert self._population is not None
        return self._population.genome, self._population.sigma

    def _survive(self, batch: Individuals, *, initial: bool) -> None:
        pool = batch if initial else Individuals.concat([self._population, batch])
        index, self._front, self._crowding = select_nsga2(pool.loss, self.batch_size)
        self._population = pool.take(index)

    def _summary(self) -> dict[str, float]:
        summary = super()._summary()
        hv = 0.0
        if self._population is not None:
            hv = hypervolume_2d(self._population.loss, self.hv_reference)
        return summary | {"hypervolume": hv}

    def settings(self) -> dict[str, object]:
        """Returns the JSON-able settings, with the hypervolume reference."""
        return super().settings() | {"hv_reference": list(self.hv_reference)}

    def _columns(self) -> dict[str, np.ndarray]:
        return {"front": self._front, "crowding": self._crowding}

    def _state(self) -> dict[str, np.ndarray]:
        return super()._state() | {"nsga2.front": self._front, "nsga2.crowding": self._crowding}

    def _load_state(self, state: dict[str, np.ndarray]) -> None:
        super()._load_state(state)
        self._front = np.asarray(state["nsga2.front"], dtype=np.int64)
        self._crowding = np.asarray(state["nsga2.crowding"], dtype=np.float64)
