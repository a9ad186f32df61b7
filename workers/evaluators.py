"""Provides the in-process evaluator and the resolution of a trial's target."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from linkevo.sim.evaluating import evaluate
from linkevo.sim.evaluation import Evaluation
from linkevo.sim.fitness import N_OBJECTIVES
from linkevo.sim.study import DEFAULT_ANGLES
from linkevo.workers.result_pool import ResultPool
from linkevo.workers.trial_spec import resolve_target

Pending = Callable[[], Evaluation]
"""A submitted batch: calling it waits for and returns its Evaluation."""


class Evaluator(Protocol):
    """Evaluates a batch of genomes for a trial."""

    def submit(self, genomes: np.ndarray) -> Pending:
        """Starts evaluating genomes (B, 56); the returned Pending gives the Evaluation,
        rows in input order. Bad genomes raise here, before any work starts."""
        ...

    def __call__(self, genomes: np.ndarray) -> Evaluation:
        """Returns the evaluation of genomes (B, 56): `submit(genomes)()`."""
        ...


class LocalEvaluator:
    """Evaluates in this process with `sim.evaluating` (numba threads over the batch).

    Results go into reused buffers (`workers.result_pool`): a buffer is written again
    only once none of its arrays is referenced, so results may be kept indefinitely.

    Args:
        fitness: the `sim.evaluating` fitness ("Fp", "Fsl", "Fp2", "Fsl2").
        mode: "paper" or "legacy".
        target: a published target name or a JSON target file.
        n_angles: crank angles per turn.
    """

    def __init__(
        self, fitness: str, mode: str, target: str = "D16", n_angles: int = DEFAULT_ANGLES
    ) -> None:
        self.fitness = fitness
        self.mode = mode
        self.target = resolve_target(target)
        self.n_angles = n_angles
        self._buffers = ResultPool(n_angles, N_OBJECTIVES.get(fitness, 1))

    def __call__(self, genomes: np.ndarray, out: Evaluation | None = None) -> Evaluation:
        """Returns the evaluation of genomes (B, 56), written into `out` when given."""
        if out is None and len(genomes):
            out = self._buffers.free(len(genomes)).evaluation().take(slice(0, len(genomes)))
        return evaluate(
            genomes,
            fitness=self.fitness,
            mode=self.mode,
            target=self.target,
            n_angles=self.n_angles,
            out=out,
        )

    def submit(self, genomes: np.ndarray) -> Pending:
        """Evaluates genomes (B, 56) now, in this thread; the Pending returns the result."""
        evaluation = self(genomes)
        return lambda: evaluation
