"""Provides evaluator actors and the evaluator that splits a batch across K of them.

Each actor gets its part of a batch as a task argument and returns its Evaluation, both
through Ray's object store (docs/grid.md, "Evaluator actors").
"""

from __future__ import annotations

import contextlib

import numpy as np
import ray
from ray.util.placement_group import PlacementGroup
from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

from linkevo.sim.evaluation import Evaluation
from linkevo.sim.genome import validate_genomes
from linkevo.workers.evaluators import LocalEvaluator, Pending


class EvaluatorWorker:
    """Evaluates genome batches with fixed settings; runs as a Ray actor.

    Args:
        fitness: the `sim.evaluating` fitness ("Fp", "Fsl", "Fp2", "Fsl2").
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
    put back in order, so the result equals one in-process `sim.evaluating` call. Use
    `start` to create the actors; `close` (or the context manager) kills them.

    Args:
        actors: `EvaluatorWorker` actors, all with the same settings.
    """

    def __init__(self, actors: list[ray.actor.ActorHandle]):
        if not actors:
            raise ValueError("ActorPoolEvaluator needs at least one actor")
        self._actors = list(actors)
        self._in_flight: Pending | None = None

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
    def actors(self) -> list[ray.actor.ActorHandle]:
        """The actors a batch is split across, in row order."""
        return list(self._actors)

    def __call__(self, genomes: np.ndarray) -> Evaluation:
        """Returns the evaluation of `genomes` (B, 56), rows in input order: `submit()()`."""
        return self.submit(genomes)()

    def submit(self, genomes: np.ndarray) -> Pending:
        """Sends the parts of `genomes` (B, 56) to the actors and returns at once.

        The returned Pending (call it once) waits for the parts and returns the Evaluation,
        rows in input order. One batch is in flight at a time: submitting before the last
        batch was collected first waits for that one and drops it.

        Raises:
            GenomeError: naming the bad row of the whole batch, before any actor is asked.
        """
        genomes = validate_genomes(genomes)
        if self._in_flight is not None:
            with contextlib.suppress(Exception):  # abandoned by the caller
                self._in_flight()
        n = len(genomes)
        n_parts = min(len(self._actors), max(n, 1))
        rows = [slice(n * i // n_parts, n * (i + 1) // n_parts) for i in range(n_parts)]
        refs = [a.evaluate.remote(genomes[r]) for a, r in zip(self._actors, rows, strict=False)]

        def collect() -> Evaluation:
            if self._in_flight is not collect:
                raise RuntimeError("this batch was collected already, or dropped by a later submit")
            self._in_flight = None
            return Evaluation.concat(ray.get(refs))

        self._in_flight = collect
        return collect

    def close(self) -> None:
        """Kills the actors (idempotent)."""
        for actor in self._actors:
            ray.kill(actor, no_restart=True)
        self._actors = []

    def __enter__(self) -> ActorPoolEvaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
