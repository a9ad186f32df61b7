"""linkevo's simulator: the 2-D linkage (`sim.linkage`: genome decoding, batched kinematics,
fitness and descriptors) and the 3-D robot that walks on it (`sim.robot`: the LEGO leg,
the walk in MuJoCo), over the study's vocabulary (`sim.study`) and the error base
(`sim.errors`). The 2-D half never imports the 3-D one.

Pure numerics (numpy, numba, MuJoCo): no Ray, MLflow, torch or file I/O. Names are
imported from their modules when first used, so `import linkevo.sim.robot.hexapod` does not load
numba or MuJoCo. Walking a robot from a linkage document, as a notebook would:

    import json
    from linkevo.sim import FLAT, FLOORS, from_document, leg_from_genome, walk

    genome, mode = from_document(json.load(open("pulled/linkage.json")))
    result = walk(leg_from_genome(genome, mode), FLOORS[FLAT])
    print(result.distance_m, result.breaks, result.reason)
"""

from __future__ import annotations

import importlib
from typing import Any

_HOMES = {
    # the 2-D linkage
    "LinkageBatch": "linkage.decoding",
    "decode": "linkage.decoding",
    "DESCRIPTOR_SPACES": "linkage.descriptors",
    "DescriptorSpace": "linkage.descriptors",
    "bin_descriptors": "linkage.descriptors",
    "evaluate": "linkage.evaluating",
    "Evaluation": "linkage.evaluation",
    "Target": "linkage.fitness",
    "named_target": "linkage.fitness",
    "N_GENES": "linkage.genome",
    "GenomeError": "linkage.genome",
    "random_genomes": "linkage.genome",
    "validate_genomes": "linkage.genome",
    "Motion": "linkage.kinematics",
    "simulate": "linkage.kinematics",
    "FITNESSES": "study",
    "PATH_FITNESSES": "study",
    "MODES": "study",
    "from_document": "linkage.linkage_doc",
    "to_document": "linkage.linkage_doc",
    # the 3-D robot
    "FLAT": "robot.hexapod",
    "CARPET": "robot.hexapod",
    "FLOORS": "robot.hexapod",
    "Leg": "robot.leg",
    "LegError": "robot.leg",
    "leg_from_genome": "robot.leg",
    "Walk": "robot.walking",
    "WalkSettings": "robot.walking",
    "field_trials": "robot.walking",
    "walk": "robot.walking",
}

__all__ = sorted(_HOMES)


def __getattr__(name: str) -> Any:
    module = _HOMES.get(name)
    if module is None:
        try:  # a submodule, e.g. `from linkevo.sim import robot`
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
