"""linkevo's simulator: genome decoding, batched kinematics, fitness and descriptors.

Pure numerics (numpy and numba): no Ray, MLflow, torch or file I/O.
"""

from linkevo.sim.decode import LinkageBatch, decode
from linkevo.sim.descriptors import DESCRIPTOR_SPACES, DescriptorSpace, bin_descriptors
from linkevo.sim.evaluate import evaluate
from linkevo.sim.evaluation import Evaluation
from linkevo.sim.fitness import Target, named_target
from linkevo.sim.genome import N_GENES, GenomeError, random_genomes, validate_genomes
from linkevo.sim.kinematics import Motion, simulate
from linkevo.sim.study import FITNESSES, MODES

__all__ = [
    "DESCRIPTOR_SPACES",
    "FITNESSES",
    "MODES",
    "N_GENES",
    "DescriptorSpace",
    "Evaluation",
    "GenomeError",
    "LinkageBatch",
    "Motion",
    "Target",
    "bin_descriptors",
    "decode",
    "evaluate",
    "named_target",
    "random_genomes",
    "simulate",
    "validate_genomes",
]
