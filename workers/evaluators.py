"""Provides the Evaluator protocol, the in-process evaluator and `make_evaluator`."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Protocol

import numpy as np

from linkevo.sim.linkage.evaluating import evaluate
from linkevo.sim.linkage.evaluation import Evaluation
from linkevo.sim.linkage.fitness import N_OBJECTIVES
from linkevo.sim.study import DEFAULT_ANGLES
from linkevo.workers.result_pool import ResultPool
from linkevo.workers.trial_spec import resolve_target

if TYPE_CHECKING:
    from linkevo.algorithms import Optimizer
    from linkevo.algorithms.optimizer import Proposer
    from linkevo.algorithms.walk_model import WalkModel
    from linkevo.workers.trial_spec import TrialSpec

Pending = Callable[[], Evaluation]
"""A submitted batch: calling it waits for and returns its Evaluation."""
Bar = Callable[[np.ndarray, Evaluation], np.ndarray]
"""The optimizer's bar (`algorithms.Optimizer.bar`): genomes (B, 56) and their 2-D
evaluation -> (B,) the loss each must get below to count."""


class Evaluator(Protocol):
    """Evaluates a batch of genomes for a trial, and keeps what the trial's checkpoint
    needs of it (a walking trial's walk log; nothing for the path fitnesses)."""

    def submit(self, genomes: np.ndarray, bar: Bar | None = None) -> Pending:
        """Starts evaluating genomes (B, 56); the returned Pending gives the Evaluation,
        rows in input order. Bad genomes raise here, before any work starts. An
        evaluator whose cost depends on how much of a candidate it must settle uses `bar`
        (the walking one); the others ignore it."""
        ...

    def __call__(self, genomes: np.ndarray) -> Evaluation:
        """Returns the evaluation of genomes (B, 56): `submit(genomes)()`."""
        ...

    def metrics(self) -> dict[str, float]:
        """Returns the evaluator's own running metrics (the walks of a walking trial)."""
        ...

    def proposals(self, optimizer: Optimizer) -> Proposer | None:
        """Returns what proposes the optimizer's batches instead of its own variation (a
        SAIL trial's rounds, `workers.walk_sail`), or None."""
        ...

    def state_dict(self) -> dict[str, np.ndarray]:
        """Returns the evaluator's state as npz-safe arrays, for the trial's checkpoint."""
        ...

    def load_state_dict(self, state: Mapping[str, np.ndarray]) -> None:
        """Restores `state_dict`'s output."""
        ...

    def close(self) -> None:
        """Releases what it holds (actors)."""
        ...


class Stateless:
    """An evaluator with no metrics or state of its own (the path fitnesses')."""

    def metrics(self) -> dict[str, float]:
        """Returns no metrics."""
        return {}

    def proposals(self, optimizer: Optimizer) -> Proposer | None:
        """Proposes nothing: the optimizer varies its own parents."""
        return None

    def state_dict(self) -> dict[str, np.ndarray]:
        """Returns no state."""
        return {}

    def load_state_dict(self, state: Mapping[str, np.ndarray]) -> None:
        """Takes nothing."""

    def close(self) -> None:
        """Holds nothing (a subclass with actors kills them)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def make_evaluator(
    spec: TrialSpec,
    actors: int = 0,
    cpus_per_actor: float = 1.0,
    placement_group: object = None,
    head_start: WalkModel | None = None,
) -> Evaluator:
    """Returns the evaluator a trial needs: in this process (`actors` = 0) or on `actors`
    evaluator actors of the running Ray instance (placed in `placement_group`'s last
    bundles); a walking trial's (`workers.walk_evaluator`) for fitness F_w, with a SAIL
    trial's rounds (`workers.walk_sail`, from the walk model `head_start`: the model of
    `spec.walk_model`, read from the store)."""
    if spec.walking_trial:
        from linkevo.workers.walk_evaluator import WalkingEvaluator

        walkers = None
        if actors:
            from linkevo.workers.ray_evaluator import ActorWalkers

            walkers = ActorWalkers.start(actors, cpus_per_actor, placement_group)
        sail = None
        if spec.surrogate == "sail":
            from linkevo.workers.walk_sail import Sail

            sail = Sail(spec.approach, spec.mode, spec.n_angles, spec.seed, spec.walks, head_start)
        two = spec.eval_fitness != spec.fitness
        return WalkingEvaluator(
            spec.mode,
            spec.n_angles,
            two_objective=two,
            walkers=walkers,
            surrogate=spec.surrogate == "screen",
            robot=spec.robot(),
            sail=sail,
        )
    if not actors:
        return LocalEvaluator(spec.eval_fitness, spec.mode, spec.target, spec.n_angles)
    from linkevo.workers.ray_evaluator import ActorPoolEvaluator

    return ActorPoolEvaluator.start(
        n_actors=actors,
        cpus_per_actor=cpus_per_actor,
        fitness=spec.eval_fitness,
        mode=spec.mode,
        target=spec.target,
        n_angles=spec.n_angles,
        placement_group=placement_group,  # type: ignore[arg-type]
    )


class LocalEvaluator(Stateless):
    """Evaluates in this process with `sim.linkage.evaluating` (numba threads over the batch).

    Results go into reused buffers (`workers.result_pool`): a buffer is written again
    only once none of its arrays is referenced, so results may be kept indefinitely.

    Args:
        fitness: the `sim.linkage.evaluating` fitness ("Fp", "Fsl", "Fp2", "Fsl2").
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

    def submit(self, genomes: np.ndarray, bar: Bar | None = None) -> Pending:
        """Evaluates genomes (B, 56) now, in this thread; the Pending returns the result
        (`bar` is not needed)."""
        evaluation = self(genomes)
        return lambda: evaluation
