"""linkevo's simulator: the 2-D linkage (genome decoding, batched kinematics, fitness and
descriptors) and the 3-D robot that walks on it (the LEGO leg, the walk in MuJoCo).

Pure numerics (numpy, numba, MuJoCo): no Ray, MLflow, torch or file I/O. Names are
imported from their modules when first used, so `import linkevo.sim.robot` does not load
numba or MuJoCo. Walking a robot from a linkage document, as a notebook would:

    import json
    from linkevo.sim import FLOORS, from_document, leg_from_genome, walk

    genome, mode = from_document(json.load(open("pulled/linkage.json")))
    result = walk(leg_from_genome(genome, mode), FLOORS["flat"])
    print(result.distance_m, result.breaks, result.reason)
"""

from __future__ import annotations

import importlib
from typing import Any

_HOMES = {
    # the 2-D linkage
    "LinkageBatch": "decoding",
    "decode": "decoding",
    "DESCRIPTOR_SPACES": "descriptors",
    "DescriptorSpace": "descriptors",
    "bin_descriptors": "descriptors",
    "evaluate": "evaluating",
    "Evaluation": "evaluation",
    "Target": "fitness",
    "named_target": "fitness",
    "N_GENES": "genome",
    "GenomeError": "genome",
    "random_genomes": "genome",
    "validate_genomes": "genome",
    "Motion": "kinematics",
    "simulate": "kinematics",
    "FITNESSES": "study",
    "PATH_FITNESSES": "study",
    "MODES": "study",
    "from_document": "linkage_doc",
    "to_document": "linkage_doc",
    # the 3-D robot
    "FLOORS": "robot",
    "Leg": "leg",
    "LegError": "leg",
    "leg_from_genome": "leg",
    "Walk": "walking",
    "WalkSettings": "walking",
    "field_trials": "walking",
    "walk": "walking",
}

__all__ = sorted(_HOMES)


def __getattr__(name: str) -> Any:
    module = _HOMES.get(name)
    if module is None:
        try:  # a submodule, e.g. `from linkevo.sim import kernels`
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return __all__
