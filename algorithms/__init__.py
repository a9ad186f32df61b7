"""linkevo's search algorithms: ask/tell optimisers on numpy arrays (no Ray, MLflow or files)."""

from linkevo.algorithms.archive import GridArchive, elite_rows
from linkevo.algorithms.ea import EvolutionaryAlgorithm
from linkevo.algorithms.factory import eval_fitness, make_optimizer
from linkevo.algorithms.individuals import Individuals
from linkevo.algorithms.map_elites import MapElites
from linkevo.algorithms.mutation import bounce_back, initial_sigma, mutate
from linkevo.algorithms.nsga2 import NSGA2
from linkevo.algorithms.optimizer import BaseOptimizer, Optimizer
from linkevo.algorithms.pareto import (
    crowding_distance,
    hypervolume_2d,
    non_dominated_ranks,
    select_nsga2,
)
from linkevo.algorithms.population import PopulationOptimizer
from linkevo.algorithms.random_sampling import RandomSampling
from linkevo.algorithms.scoring import (
    HV_REFERENCES,
    QD_OFFSETS,
    scalar_loss,
)
from linkevo.algorithms.selection import tournament

__all__ = [
    "HV_REFERENCES",
    "NSGA2",
    "QD_OFFSETS",
    "BaseOptimizer",
    "EvolutionaryAlgorithm",
    "GridArchive",
    "Individuals",
    "MapElites",
    "Optimizer",
    "PopulationOptimizer",
    "RandomSampling",
    "bounce_back",
    "crowding_distance",
    "elite_rows",
    "eval_fitness",
    "hypervolume_2d",
    "initial_sigma",
    "make_optimizer",
    "mutate",
    "non_dominated_ranks",
    "scalar_loss",
    "select_nsga2",
    "tournament",
]
