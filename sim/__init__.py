"""linkevo's simulator: genome decoding, batched kinematics, fitness and descriptors.

Pure numerics (numpy and numba): no Ray, MLflow, torch or file I/O.
"""

from sim.decode import LinkageBatch, decode
from sim.descriptors import DESCRIPTOR_SPACES, DescriptorSpace, bin_descriptors
from sim.evaluate import evaluate
from sim.evaluation import FITNESSES, MODES, Evaluation
from sim.fitness import Target, named_target
from sim.genome import N_GENES, GenomeError, random_genomes, validate_genomes
from sim.kinematics import Motion, simulate

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
