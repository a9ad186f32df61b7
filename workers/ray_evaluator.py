"""Provides evaluator actors and the evaluator that splits a batch across K of them."""

from __future__ import annotations

import numpy as np
import ray
from ray.util.placement_group import PlacementGroup
from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

from sim.evaluation import Evaluation
from workers.evaluators import LocalEvaluator


class EvaluatorWorker:
    """Evaluates genome batches with fixed settings; runs as a Ray actor.

    Args:
        fitness: the `sim.evaluate` fitness ("Fp", "Fsl", "Fp2", "Fsl2").
        mode: "paper" or "legacy".
        target: a published target name or a JSON target file.
        n_angles: crank angles per linkage.
        threads: numba threads this worker may use (its reserved CPUs).
    """

    def __init__(self, *, fitness: str, mode: str, target: str, n_angles: int, threads: int):
        import numba

        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
        self._evaluate = LocalEvaluator(fitness, mode, target, n_angles)

    def evaluate(self, genomes: np.ndarray) -> Evaluation:
        """Returns the evaluation of `genomes` (B, 56)."""
        return self._evaluate(genomes)


class ActorPoolEvaluator:
    """Evaluates a batch by splitting it by index across K evaluator actors.

    The batch is cut into K contiguous parts (one per actor), evaluated concurrently and
    concatenated back in order, so the result equals one in-process `sim.evaluate` call.
    Use `start` to create the actors; `close` (or the context manager) kills them.
    """

    def __init__(self, actors: list[ray.actor.ActorHandle]):
        if not actors:
            raise ValueError("ActorPoolEvaluator needs at least one actor")
        self._actors = actors

    @classmethod
    def start(
        cls,
        *,
        n_actors: int,
        cpus_per_actor: float,
        fitness: str,
        mode: str,
        target: str,
        n_angles: int,
        placement_group: PlacementGroup | None = None,
    ) -> ActorPoolEvaluator:
        """Returns an evaluator with `n_actors` new actors reserving `cpus_per_actor` each.

        With a placement group, actor i takes bundle `len(bundles) - n_actors + i` (the
        last n_actors bundles; an earlier bundle may hold the trial task itself).
        """
        remote_cls = ray.remote(EvaluatorWorker)
        first_bundle = 0
        if placement_group is not None:
            first_bundle = len(placement_group.bundle_specs) - n_actors
        actors = []
        for i in range(n_actors):
            strategy = None
            if placement_group is not None:
                strategy = PlacementGroupSchedulingStrategy(
                    placement_group=placement_group,
                    placement_group_bundle_index=first_bundle + i,
                )
            options = remote_cls.options(
                num_cpus=cpus_per_actor,
                max_restarts=1,
                max_task_retries=1,
                scheduling_strategy=strategy,
            )
            actors.append(
                options.remote(
                    fitness=fitness,
                    mode=mode,
                    target=target,
                    n_angles=n_angles,
                    threads=max(1, int(cpus_per_actor)),
                )
            )
        return cls(actors)

    @property
    def n_actors(self) -> int:
        """The number of actors a batch is split across."""
        return len(self._actors)

    def __call__(self, genomes: np.ndarray) -> Evaluation:
        """Returns the evaluation of `genomes` (B, 56), rows in input order."""
        n_parts = min(len(self._actors), max(len(genomes), 1))
        parts = np.array_split(genomes, n_parts)
        refs = [
            actor.evaluate.remote(part) for actor, part in zip(self._actors, parts, strict=False)
        ]
        return Evaluation.concat(ray.get(refs))

    def close(self) -> None:
        """Kills the actors (idempotent)."""
        for actor in self._actors:
            ray.kill(actor, no_restart=True)
        self._actors = []

    def __enter__(self) -> ActorPoolEvaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
