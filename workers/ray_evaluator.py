"""Provides evaluator actors: the evaluator that splits a batch across K of them, and the
walkers of a walking trial (`ActorWalkers`).

Each actor gets its part of a batch as a task argument and returns its Evaluation, both
through Ray's object store (docs/grid.md, "Evaluator actors"). A walking trial's actors
take its candidates one task each, so that the one that finishes first takes the next.
"""

from __future__ import annotations

import contextlib

import numpy as np
import ray
from ray.util.placement_group import PlacementGroup
from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

from linkevo.sim.linkage.evaluation import Evaluation
from linkevo.sim.linkage.genome import validate_genomes
from linkevo.sim.robot.hexapod import Robot
from linkevo.sim.robot.walk_fitness import CandidateWalk, walk_candidate
from linkevo.workers.evaluators import Bar, LocalEvaluator, Pending, Stateless


def actor_options(
    worker: type, n_actors: int, cpus: float, placement_group: PlacementGroup | None
) -> list:
    """Returns how to start each of `n_actors` actors of `worker` reserving `cpus` each.

    With a placement group, actor i takes bundle `len(bundles) - n_actors + i` (the last
    n_actors bundles; an earlier bundle may hold the trial task itself). An actor whose
    node dies is restarted once, and its task retried once."""
    remote_cls = ray.remote(worker)
    first_bundle = 0
    if placement_group is not None:
        first_bundle = len(placement_group.bundle_specs) - n_actors
    out = []
    for i in range(n_actors):
        strategy = None
        if placement_group is not None:
            strategy = PlacementGroupSchedulingStrategy(
                placement_group=placement_group, placement_group_bundle_index=first_bundle + i
            )
        out.append(
            remote_cls.options(
                num_cpus=cpus, max_restarts=1, max_task_retries=1, scheduling_strategy=strategy
            )
        )
    return out


class EvaluatorWorker:
    """Evaluates genome batches with fixed settings; runs as a Ray actor.

    Args:
        fitness: the `sim.linkage.evaluating` fitness ("Fp", "Fsl", "Fp2", "Fsl2").
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


class ActorPoolEvaluator(Stateless):
    """Evaluates a batch by splitting it by index across K evaluator actors.

    The batch is cut into K contiguous parts (one per actor), evaluated concurrently and
    put back in order, so the result equals one in-process `sim.linkage.evaluating` call. Use
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
        actors = [
            options.remote(
                fitness=fitness,
                mode=mode,
                target=target,
                n_angles=n_angles,
                threads=max(1, int(cpus_per_actor)),
            )
            for options in actor_options(EvaluatorWorker, n_actors, cpus_per_actor, placement_group)
        ]
        return cls(actors)

    @property
    def actors(self) -> list[ray.actor.ActorHandle]:
        """The actors a batch is split across, in row order."""
        return list(self._actors)

    def __call__(self, genomes: np.ndarray) -> Evaluation:
        """Returns the evaluation of `genomes` (B, 56), rows in input order: `submit()()`."""
        return self.submit(genomes)()

    def submit(self, genomes: np.ndarray, bar: Bar | None = None) -> Pending:
        """Sends the parts of `genomes` (B, 56) to the actors and returns at once (`bar`
        is not needed).

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


class WalkWorker:
    """Builds and walks a walking trial's candidates; runs as a Ray actor."""

    def walk(
        self,
        genome: np.ndarray,
        mode: str,
        known: frozenset[str],
        bar: float,
        robot: Robot,
        searched: np.ndarray,
    ) -> tuple[CandidateWalk, str]:
        """Returns the candidate's walk (`sim.robot.walk_fitness.walk_candidate`) and this
        actor's Ray node."""
        node = ray.get_runtime_context().get_node_id()
        return walk_candidate(genome, mode, known, bar, robot=robot, searched=searched), node


class ActorWalkers:
    """A walking trial's candidates built and walked on its evaluator actors, a task each
    (`ray.util.ActorPool`: an actor takes the next candidate as soon as it is free).

    Args:
        actors: `WalkWorker` actors.
    """

    def __init__(self, actors: list[ray.actor.ActorHandle]):
        if not actors:
            raise ValueError("ActorWalkers needs at least one actor")
        self._actors = list(actors)

    @classmethod
    def start(
        cls, n_actors: int, cpus_per_actor: float, placement_group: PlacementGroup | None = None
    ) -> ActorWalkers:
        """Returns walkers on `n_actors` new actors (placed as `actor_options` says)."""
        options = actor_options(WalkWorker, n_actors, cpus_per_actor, placement_group)
        return cls([o.remote() for o in options])

    def walk(
        self,
        genomes: np.ndarray,
        mode: str,
        known: frozenset[str],
        bars: np.ndarray,
        robot: Robot,
        searched: np.ndarray,
    ):
        """Starts every candidate's walk now; yields each (walk, node) in order."""
        from ray.util import ActorPool

        known_ref = ray.put(known)
        pool = ActorPool(self._actors)
        items = list(zip(genomes, bars.tolist(), searched, strict=True))
        return pool.map(
            lambda actor, i: actor.walk.remote(i[0], mode, known_ref, i[1], robot, i[2]), items
        )

    def close(self) -> None:
        """Kills the actors (idempotent)."""
        for actor in self._actors:
            ray.kill(actor, no_restart=True)
        self._actors = []
