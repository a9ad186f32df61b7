"""Provides `evaluate`: decode, simulate and score a batch of genomes in one kernel (and
`evaluate_with_motion`, which keeps the decoding and motion it computed)."""

from __future__ import annotations

import dataclasses
import itertools

import numba
import numpy as np

from linkevo.sim.linkage import kernels
from linkevo.sim.linkage.decoding import LinkageBatch, check_mode
from linkevo.sim.linkage.evaluation import Evaluation, field_shapes
from linkevo.sim.linkage.fitness import (
    FITNESS_CODES,
    N_OBJECTIVES,
    Target,
    check_fitness,
    named_target,
)
from linkevo.sim.linkage.genome import MAX_BEAMS, N_NODES, validate_genomes
from linkevo.sim.linkage.kinematics import Motion, check_angles
from linkevo.sim.study import DEFAULT_ANGLES


def evaluate(
    genomes: np.ndarray,
    fitness: str = "Fp",
    mode: str = "paper",
    target: Target | str | None = None,
    n_angles: int = DEFAULT_ANGLES,
    out: Evaluation | None = None,
) -> Evaluation:
    """Returns the Evaluation of genomes (N, 56): losses, errors, foot paths, descriptors.

    Args:
        genomes: (N, 56) genes in [0, 1).
        fitness: "Fp", "Fsl" (loss (N,)) or "Fp2", "Fsl2" (loss (N, 2)).
        mode: "paper" (default) or "legacy".
        target: F_p target points, or a published name ("D16", "D24"); None is "D16".
        n_angles: crank angles per turn, A.
        out: where to write the results (then returned), e.g. from `Evaluation.empty`;
            its arrays must have the shapes and dtypes of this call's result. None
            allocates new arrays.

    Raises:
        ValueError: for bad genomes (`sim.linkage.genome.GenomeError`), an unknown fitness or
            mode, n_angles < MIN_ANGLES or an `out` of the wrong layout; raised before any work
            starts.
    """
    return _evaluate(genomes, fitness, mode, target, n_angles, out, keep=False)[0]


def evaluate_with_motion(
    genomes: np.ndarray,
    fitness: str = "Fp",
    mode: str = "paper",
    target: Target | str | None = None,
    n_angles: int = DEFAULT_ANGLES,
) -> tuple[Evaluation, LinkageBatch, Motion]:
    """Returns the Evaluation of genomes (N, 56) with their decoding and motion, from the one
    kernel pass: the same, bit for bit, as `decode(genomes, mode)` and `simulate(batch,
    n_angles)` give, for a caller that reads all three (a walking trial's batch); arguments
    and errors as `evaluate`'s."""
    evaluation, kept = _evaluate(genomes, fitness, mode, target, n_angles, None, keep=True)
    return evaluation, *kept


def _evaluate(genomes, fitness, mode, target, n_angles, out, *, keep: bool):
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
    if out is None:
        out = Evaluation.empty(n, n_angles, n_obj)
    else:
        check_out(out, n, n_angles, n_obj, genomes)
    size = n if keep else 0
    batch = LinkageBatch(
        mode=mode,
        node_int=np.empty((size, N_NODES, 4), np.int64),
        node_float=np.empty((size, N_NODES, 5)),
        beam_int=np.empty((size, MAX_BEAMS, 6), np.int64),
        beam_length=np.empty((size, MAX_BEAMS)),
        n_beams=np.empty(size, np.int64),
        positions0=np.empty((size, N_NODES, 2)),
    )
    motion = Motion(
        positions=np.empty((size, N_NODES, n_angles, 2)),
        valid=out.valid if keep else np.empty((0, n_angles), np.bool_),
        beam_angles=np.full((size, MAX_BEAMS, n_angles), np.nan),
        foot=out.foot if keep else np.empty(0, np.int64),
    )
    if n:
        d = out.descriptors
        kernels.evaluate_batch(
            genomes,
            legacy,
            n_angles,
            FITNESS_CODES[fitness],
            target.points,
            target.is_step,
            min(n, 16 * numba.get_num_threads()),
            out.loss.reshape(n, n_obj),
            out.error,
            out.angle_error,
            out.valid,
            out.foot,
            out.foot_x,
            out.foot_y,
            d["MAP-WH"],
            d["MAP-LIS"],
            d["MAP-ST"],
            keep,
            batch.node_int,
            batch.node_float,
            batch.beam_int,
            batch.beam_length,
            batch.n_beams,
            batch.positions0,
            motion.positions,
            motion.beam_angles,
        )
    if keep:  # the motion's own copies: a caller may change the evaluation
        motion = dataclasses.replace(motion, valid=out.valid.copy(), foot=out.foot.copy())
    return out, (batch, motion)


def check_out(
    out: Evaluation, n: int, n_angles: int, n_objectives: int, genomes: np.ndarray
) -> None:
    """Raises ValueError unless `out` holds writable, C-contiguous arrays of the shapes and
    dtypes of an Evaluation of n genomes over n_angles with n_objectives losses, none of
    them overlapping another or the (C-contiguous) genomes: the kernel's helpers assume
    that their arrays never overlap (`sim.linkage.kernels._JIT`)."""
    arrays = out.arrays()
    for name, shape, dtype in field_shapes(n, n_angles, n_objectives):
        array = arrays.get(name)
        if not (
            isinstance(array, np.ndarray)
            and array.shape == shape
            and array.dtype == dtype
            and array.flags.c_contiguous
            and array.flags.writeable
        ):
            got = repr(array) if not isinstance(array, np.ndarray) else (array.shape, array.dtype)
            raise ValueError(
                f"out {name} must be a writable C-contiguous {np.dtype(dtype)} array of "
                f"shape {shape}, got {got}"
            )
    spans = sorted(
        (a.ctypes.data, a.ctypes.data + a.nbytes, name)
        for name, a in {"genomes": genomes, **{f"out {k}": v for k, v in arrays.items()}}.items()
        if a.nbytes
    )
    for (_, end, first), (start, _, second) in itertools.pairwise(spans):
        if start < end:  # sorted by start, so any overlap shows between neighbours
            raise ValueError(
                f"{second} overlaps {first} in memory; every result needs an array of "
                "its own, apart from the genomes"
            )
