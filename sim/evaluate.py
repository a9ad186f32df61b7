"""Provides `evaluate`: decode, simulate and score a batch of genomes in one kernel."""

from __future__ import annotations

import numba
import numpy as np

from sim import kernels
from sim.decode import check_mode
from sim.evaluation import Evaluation
from sim.fitness import FITNESS_CODES, N_OBJECTIVES, Target, check_fitness, named_target
from sim.genome import validate_genomes
from sim.kinematics import DEFAULT_ANGLES, check_angles


def evaluate(
    genomes: np.ndarray,
    fitness: str = "Fp",
    mode: str = "paper",
    target: Target | str | None = None,
    n_angles: int = DEFAULT_ANGLES,
) -> Evaluation:
    """Returns the Evaluation of genomes (N, 56): losses, errors, foot paths, descriptors.

    Args:
        genomes: (N, 56) genes in [0, 1).
        fitness: "Fp", "Fsl" (loss (N,)) or "Fp2", "Fsl2" (loss (N, 2)).
        mode: "paper" (default) or "legacy".
        target: F_p target points, or a published name ("D16", "D24"); None is "D16".
        n_angles: crank angles per turn, A.

    Raises:
        ValueError: for bad genomes (`sim.genome.GenomeError`), an unknown fitness or
            mode, or n_angles < 2; raised before any work starts.
    """
    legacy = check_mode(mode)
    check_fitness(fitness)
    n_angles = check_angles(n_angles)
    genomes = validate_genomes(genomes)
    if target is None or isinstance(target, str):
        target = named_target(target or "D16")
    elif not isinstance(target, Target):
        raise ValueError(f"target must be a Target or a published name, got {target!r}")
    n = genomes.shape[0]
    n_obj = N_OBJECTIVES[fitness]
    loss = np.empty((n, n_obj))
    error = np.empty(n, np.int64)
    angle_error = np.empty(n)
    valid = np.empty((n, n_angles), np.bool_)
    foot = np.empty(n, np.int64)
    foot_x = np.empty((n, n_angles))
    foot_y = np.empty((n, n_angles))
    wh = np.empty((n, 2))
    lis = np.empty((n, 2))
    st = np.empty((n, 4))
    if n:
        kernels.evaluate_batch(
            genomes, legacy, n_angles, FITNESS_CODES[fitness], target.points, target.is_step,
            min(n, 16 * numba.get_num_threads()),
            loss, error, angle_error, valid, foot, foot_x, foot_y, wh, lis, st,
        )  # fmt: skip
    return Evaluation(
        loss=loss[:, 0] if n_obj == 1 else loss,
        error=error,
        angle_error=angle_error,
        valid=valid,
        foot=foot,
        foot_x=foot_x,
        foot_y=foot_y,
        descriptors={"MAP-WH": wh, "MAP-LIS": lis, "MAP-ST": st},
    )
