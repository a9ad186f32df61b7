"""Prints a fingerprint of a small MAP-AU trial: the SHA-256 of its repertoire (cells,
genomes, descriptors, losses) and of its encoder's weights and Adagrad sums.

Run as `python -m tests.helpers.aurora_fingerprint`, with `NUMBA_CPU_NAME` choosing the
CPU numba compiles for (`tests/algorithms/test_aurora_reproducible.py`).
"""

from __future__ import annotations

import hashlib
import json

import numpy as np

from linkevo.algorithms.aurora import AuroraMapElites
from linkevo.sim import evaluate

SCHEDULE = {
    "initial_epochs": 6,
    "retrain_epochs": 4,
    "retrain_period": 2,
    "ae_batch_size": 32,
    "learning_rate": 0.01,
}
"""Training sessions at iterations 1, 3 and 5 (each re-places every elite), small enough
for a test."""


def fingerprint(seed: int = 5, iterations: int = 5, batch_size: int = 500) -> dict[str, str]:
    """Returns {"repertoire": sha256, "encoder": sha256, "elites": count} of a MAP-AU trial
    on F_p in paper mode."""
    optimizer = AuroraMapElites(
        fitness="Fp", batch_size=batch_size, mode="paper", seed=seed, **SCHEDULE
    )
    for _ in range(iterations):
        genomes = optimizer.ask()
        optimizer.tell(genomes, evaluate(genomes, "Fp", "paper"))
    elites = optimizer.archive.elites
    repertoire = hashlib.sha256()
    for array in (optimizer.archive.cells, elites.genome, elites.desc, elites.loss):
        repertoire.update(np.ascontiguousarray(array).tobytes())
    encoder = hashlib.sha256()
    for name, tensor in sorted(optimizer.torch_state().items()):
        encoder.update(name.encode() + tensor.numpy().tobytes())
    return {
        "repertoire": repertoire.hexdigest(),
        "encoder": encoder.hexdigest(),
        "elites": str(len(elites.loss)),
    }


if __name__ == "__main__":
    print(json.dumps(fingerprint()))
