"""Provides evaluator actors and the evaluator that splits a batch across K of them.

Actors on the caller's Ray node exchange batches through a `SharedBatch` file and take
requests on a side channel (`workers.channel`); others go through Ray's object store
(docs/grid.md, "Evaluator transport").
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Callable
from multiprocessing.connection import Connection

import numpy as np
import ray
from ray.util.placement_group import PlacementGroup
from ray.util.scheduling_strategies import PlacementGroupSchedulingStrategy

from linkevo.sim.evaluation import Evaluation
from linkevo.sim.fitness import N_OBJECTIVES
from linkevo.sim.genome import validate_genomes
from linkevo.workers import channel
from linkevo.workers.evaluators import LocalEvaluator, Pending
from linkevo.workers.result_pool import KEEP, ResultPool
from linkevo.workers.shared_batch import SharedBatch, SharedLayout, shared_memory_available


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

        self._threads = max(1, min(threads, numba.config.NUMBA_NUM_THREADS))
        numba.set_num_threads(self._threads)
        self._evaluate = LocalEvaluator(fitness, mode, target, n_angles)
        self._attached: dict[SharedLayout, SharedBatch] = {}

    def evaluate(self, genomes: np.ndarray) -> Evaluation:
        """Returns the evaluation of `genomes` (B, 56)."""
        return self._evaluate(genomes)

    def open_channel(self, node_id: str, authkey: bytes) -> str | None:
        """Serves `evaluate_shared` on a side channel for a caller on Ray node `node_id`.

        Returns the channel's address, or None when this actor runs on another node.
        """
        if node_id != ray.get_runtime_context().get_node_id():
            return None
        import numba

        def setup() -> None:
            numba.set_num_threads(self._threads)  # numba's thread count is per thread

        return channel.serve(self.evaluate_shared, authkey, setup)

    def evaluate_shared(self, layout: tuple, start: int, stop: int) -> bool:
        """Evaluates rows start:stop of a SharedBatch's genomes into its Evaluation.

        `layout` is `SharedLayout.as_tuple()`. Returns False, doing nothing, when the batch
        lives on another Ray node. The last KEEP batches stay mapped.
        """
        found = SharedLayout(*layout)
        if found.node_id != ray.get_runtime_context().get_node_id():
            return False
        batch = self._attached.pop(found, None) or SharedBatch.attach(found)
        self._attached[found] = batch  # most recently used last
        while len(self._attached) > KEEP:
            del self._attached[next(iter(self._attached))]
        rows = slice(start, stop)
        self._evaluate(batch.genomes[rows], out=batch.evaluation().take(rows))
        return True


class ActorPoolEvaluator:
    """Evaluates a batch by splitting it by index across K evaluator actors.

    The batch is cut into K contiguous parts (one per actor), evaluated concurrently and
    put back in order, so the result equals one in-process `sim.evaluate` call.
    With `shared_memory` (and a writable /dev/shm), the genomes and results pass through
    a `SharedBatch` file and the returned Evaluation's arrays are views into it; the file
    is reused only once none of them is alive any more, so a caller may keep results as
    long as it likes (a new file is made meanwhile). Requests to actors on this node go
    over a side channel (`workers.channel`), falling back to a Ray call when an actor's
    channel is lost (Ray restarts the actor; the next batch opens a new channel). An actor
    on another node gets and returns its part through the object store instead. Use
    `start` to create the actors; `close` (or the context manager) kills them and deletes
    the files.

    Args:
        actors: `EvaluatorWorker` actors, all with the same settings.
        n_angles: their crank angles per linkage.
        n_objectives: their losses per genome (1, or 2 for Fp2/Fsl2).
        shared_memory: pass batches through a shared-memory file where possible.

    Attributes:
        parts_by_transport: how many batch parts went through "shared-file" and
            "object-store" so far.
    """

    def __init__(
        self,
        actors: list[ray.actor.ActorHandle],
        *,
        n_angles: int,
        n_objectives: int,
        shared_memory: bool = True,
    ):
        if not actors:
            raise ValueError("ActorPoolEvaluator needs at least one actor")
        self._actors = actors
        self._n_angles = n_angles
        self._n_objectives = n_objectives
        self._batches: ResultPool | None = None
        if shared_memory and shared_memory_available():
            self._batches = ResultPool(self._new_batch)
        self._channels: dict[int, Connection | None] = {}
        self._authkey = os.urandom(32)
        self.parts_by_transport = {"shared-file": 0, "object-store": 0}
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
        shared_memory: bool = True,
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
        return cls(
            actors,
            n_angles=n_angles,
            n_objectives=N_OBJECTIVES[fitness],
            shared_memory=shared_memory,
        )

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
        actors = self._actors[:n_parts]
        if self._batches is None or n == 0:
            refs = [a.evaluate.remote(genomes[r]) for a, r in zip(actors, rows, strict=True)]
            self.parts_by_transport["object-store"] += len(refs)
            return self._track(lambda: Evaluation.concat(ray.get(refs)))
        try:
            shared = self._batches.free(n)
        except OSError as exc:
            warnings.warn(
                f"shared-memory batches unavailable ({exc}); using Ray's object store",
                RuntimeWarning,
                stacklevel=2,
            )
            self._batches.close()
            self._batches = None
            return self.submit(genomes)
        shared.genomes[:n] = genomes
        layout = shared.layout.as_tuple()
        answers = self._send_shared(actors, [(layout, r.start, r.stop) for r in rows])

        def collect() -> Evaluation:
            result = shared.evaluation().take(slice(0, n))
            missing = [i for i, ok in enumerate(answers()) if not ok]
            remote = [actors[i].evaluate.remote(genomes[rows[i]]) for i in missing]
            for i, part in zip(missing, ray.get(remote), strict=True):
                rows_out = result.take(rows[i]).arrays()
                for name, values in part.arrays().items():
                    rows_out[name][...] = values
            self.parts_by_transport["object-store"] += len(missing)
            self.parts_by_transport["shared-file"] += len(rows) - len(missing)
            return result

        return self._track(collect)

    def _track(self, collect: Pending) -> Pending:
        """Returns `collect` as the batch in flight, to be called once."""

        def pending() -> Evaluation:
            if self._in_flight is not pending:
                raise RuntimeError("this batch was collected already, or dropped by a later submit")
            self._in_flight = None
            return collect()

        self._in_flight = pending
        return pending

    def _send_shared(self, actors: list, requests: list[tuple]) -> Callable[[], list[bool]]:
        """Sends request i to actor i (its channel, else a Ray call); returns a function
        that waits for the answers (True: done, False: the actor is on another node)."""
        sent: dict[int, Connection] = {}
        refs = {}
        for i, (actor, request) in enumerate(zip(actors, requests, strict=True)):
            conn = self._channel(i)
            if conn is not None:
                try:
                    conn.send(request)
                    sent[i] = conn
                    continue
                except OSError:  # the actor is gone; Ray restarts it
                    self._channels.pop(i)
            refs[i] = actor.evaluate_shared.remote(*request)

        def answers() -> list[bool]:
            try:
                done = channel.replies(sent)
            except channel.ChannelLost as lost:
                done = lost.answers
                for i in lost.lost:  # Ray restarts the actor; its channel reopens next batch
                    self._channels.pop(i)
                    refs[i] = actors[i].evaluate_shared.remote(*requests[i])
                for answer in done.values():
                    if isinstance(answer, Exception):
                        raise answer from None
            if refs:  # even an empty ray.get costs about 0.25 ms
                done.update(zip(refs, ray.get(list(refs.values())), strict=True))
            return [bool(done[i]) for i in range(len(requests))]

        return answers

    def _channel(self, i: int) -> Connection | None:
        """Returns actor i's side channel, opening it on first use (None: another node)."""
        if i not in self._channels:
            node = ray.get_runtime_context().get_node_id()
            address = ray.get(self._actors[i].open_channel.remote(node, self._authkey))
            self._channels[i] = None if address is None else channel.connect(address, self._authkey)
        return self._channels[i]

    def _new_batch(self, n: int) -> SharedBatch:
        node = ray.get_runtime_context().get_node_id()
        return SharedBatch.create(node, n, self._n_angles, self._n_objectives)

    def close(self) -> None:
        """Closes the channels, kills the actors, deletes the batch files (idempotent)."""
        for conn in self._channels.values():
            if conn is not None:
                conn.close()
        self._channels = {}
        for actor in self._actors:
            ray.kill(actor, no_restart=True)
        self._actors = []
        if self._batches is not None:
            self._batches.close()

    def __enter__(self) -> ActorPoolEvaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
