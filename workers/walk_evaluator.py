"""Provides `WalkingEvaluator`: a walking trial's evaluator (fitness F_w, `sim.robot.walk_fitness`).

A batch is evaluated as the path fitnesses are (the 2-D kernel gives every candidate its
foot path and descriptors, and keeps its decoding and motion, which the 2-D checks, the
LEGO builds and the walk model's features read), then screened: a candidate that fails the
2-D checks is rejected at no walk's cost; the others are built for the whole batch at once
(`sim.robot.builds.build_lengths`: each candidate decoded, simulated in 2-D and built once
a round, for the pre-screen's features and its walk alike) and walked as their LEGO legs,
here or on the trial's evaluator actors (`ActorWalkers`), each candidate a task, so that an actor
that finishes early takes the next. A leg already walked in the trial is not walked
again: its rows are reused (the walk is deterministic). The evaluator keeps the trial's
walk log (`workers.walk_log.WalkLog`: every candidate it built, with its rows, the seconds
it took and the Ray node that walked it), which is its checkpointed state and, at the
trial's end, its `walks.parquet` and the walk map of what the trial kept.
"""

from __future__ import annotations

import dataclasses
import socket
from collections.abc import Callable, Iterator, Mapping
from typing import TYPE_CHECKING, Protocol

import numpy as np

from linkevo.sim.linkage.evaluating import evaluate_with_motion
from linkevo.sim.linkage.evaluation import Evaluation
from linkevo.sim.linkage.genome import validate_genomes
from linkevo.sim.linkage.physical import physical_checks
from linkevo.sim.robot.builds import build_lengths, study_rows
from linkevo.sim.robot.hexapod import Robot
from linkevo.sim.robot.walk_features import features_of
from linkevo.sim.robot.walk_fitness import (
    CandidateWalk,
    floor_losses,
    rejected_loss,
    walk_candidate,
)
from linkevo.sim.robot.walk_rows import Stage
from linkevo.workers.evaluators import Bar, Pending
from linkevo.workers.seed_repertoire import Seed
from linkevo.workers.walk_log import WalkLog

if TYPE_CHECKING:
    from linkevo.algorithms import Optimizer
    from linkevo.algorithms.optimizer import Proposer
    from linkevo.workers.walk_sail import Sail


class Walkers(Protocol):
    """Where a batch's candidates are built and walked."""

    def walk(
        self,
        genomes: np.ndarray,
        mode: str,
        known: frozenset[str],
        bars: np.ndarray,
        robot: Robot,
        searched: np.ndarray,
    ) -> Iterator[tuple[CandidateWalk, str]]:
        """Yields each candidate's walk (`sim.robot.walk_fitness.walk_candidate`, legs in
        `known` not walked, each with its bar (K,) and its build's lengths (K, 15), on
        `robot`) and where it ran, in order."""
        ...

    def close(self) -> None:
        """Releases what the walkers hold."""
        ...


class LocalWalkers:
    """Builds and walks every candidate in this process, one after another."""

    def walk(
        self,
        genomes: np.ndarray,
        mode: str,
        known: frozenset[str],
        bars: np.ndarray,
        robot: Robot,
        searched: np.ndarray,
    ):
        host = socket.gethostname()
        for genome, bar, lengths in zip(genomes, bars, searched, strict=True):
            yield (
                walk_candidate(genome, mode, known, float(bar), robot=robot, searched=lengths),
                host,
            )

    def close(self) -> None:
        """Nothing to release."""


class WalkingEvaluator:
    """Evaluates a walking trial's batches (F_w, or F_w2 for a multi-objective approach).

    Args:
        mode: "paper" or "legacy".
        n_angles: crank angles of the 2-D evaluation.
        two_objective: return each floor's loss (B, 2) rather than the worse one (B,).
        walkers: where candidates are walked (`LocalWalkers`, `ActorWalkers`).
        robot: the robot walked (default: the study's robot).
        surrogate: pre-screen the candidates with the learned walk model fitted on the
            trial's walks (`workers.walk_surrogate`); single-objective only.
        sail: run the trial's search in the walk model (`workers.walk_sail`): its
            `proposals` choose the batches, and no batch is walked past the budget.
    """

    def __init__(
        self,
        mode: str,
        n_angles: int,
        two_objective: bool,
        walkers: Walkers | None = None,
        surrogate: bool = False,
        robot: Robot | None = None,
        sail: Sail | None = None,
    ) -> None:
        self.mode = mode
        self.robot = robot or Robot()
        self.n_angles = n_angles
        self.two_objective = two_objective
        self.walkers = walkers or LocalWalkers()
        self.surrogate = None
        if surrogate:
            from linkevo.workers.walk_surrogate import WalkSurrogate

            self.surrogate = WalkSurrogate(mode)
        self.sail = sail
        self.log = WalkLog.empty()
        self._iteration = 0
        self._in_flight: Callable[[], Evaluation] | None = None
        self._seeded: dict[bytes, dict[str, dict]] = {}

    def seed_with(self, seed: Seed) -> None:
        """Takes a warm start's rows: its genomes are told with them, not walked."""
        self._seeded = {g.tobytes(): rows for g, rows in zip(seed.genomes, seed.rows, strict=True)}

    def __call__(self, genomes: np.ndarray) -> Evaluation:
        """Returns the evaluation of genomes (B, 56): `submit(genomes)()`."""
        return self.submit(genomes)()

    def submit(self, genomes: np.ndarray, bar: Bar | None = None) -> Pending:
        """Screens genomes (B, 56) and starts walking those that pass; the Pending returns
        the Evaluation, rows in input order, once every walk is back (and logged).

        Args:
            genomes: (B, 56).
            bar: the optimizer's bar (`algorithms.Optimizer.bar`) on the batch's 2-D
                evaluation: a candidate is walked on its second floor only when its first
                leaves it a chance to get below.

        Raises:
            GenomeError: naming the bad row, before any work starts.
        """
        genomes = validate_genomes(genomes)
        if self._in_flight is not None:
            raise RuntimeError("collect the last batch before submitting another")
        self._iteration += 1
        iteration = self._iteration
        base, batch, motion = evaluate_with_motion(genomes, "Fp", self.mode, n_angles=self.n_angles)
        checks = physical_checks(batch, motion)
        seeded = [self._seeded.get(g.tobytes()) for g in genomes]
        reused = np.array([r is not None for r in seeded])
        built = np.flatnonzero(checks.buildable & ~reused)
        bars = np.full(len(genomes), np.inf) if bar is None else bar(genomes, base)
        skipped = np.zeros(0, np.int64)
        rows, here = study_rows(batch, motion, built)
        searched = build_lengths(rows, here)  # each candidate built once: features and walk
        if self.surrogate is not None:
            self.surrogate.refresh(self.log)
            worth = self.surrogate.worth_walking(
                lambda: features_of(rows, here, searched), bars[built]
            )
            built, skipped, searched = built[worth], built[~worth], searched[worth]
        if self.sail is not None:  # a SAIL trial never walks past its budget
            left = max(self.sail.walks - self.log.counts["walks"], 0)
            built, skipped = built[:left], np.concatenate([skipped, built[left:]])
            searched = searched[:left]
        known = self.log.known()
        walks = self.walkers.walk(
            genomes[built], self.mode, frozenset(known), bars[built], self.robot, searched
        )

        def collect() -> Evaluation:
            self._in_flight = None
            losses = np.repeat(rejected_loss(base.error, checks)[:, None], 2, axis=1)
            losses[skipped] = np.inf  # not walked: it enters no archive
            done = [(CandidateWalk(Stage.SEEDED, "", (), 0.0), "") for _ in np.flatnonzero(reused)]
            done += list(walks)
            rows = [seeded[i] for i in np.flatnonzero(reused)]
            built_now = np.concatenate([np.flatnonzero(reused), built]).astype(np.int64)
            for i, (walk, _) in zip(built_now, done, strict=True):
                if walk.stage == Stage.SEEDED:
                    losses[i] = floor_losses(Stage.SEEDED, seeded[i])
                    continue
                by_floor = known[walk.key] if walk.stage == Stage.CACHED else _by_floor(walk)
                losses[i] = floor_losses(walk.stage, by_floor)
                rows.append(by_floor)
            self.log.counts["walks_skipped"] += len(skipped)
            self._tally(len(genomes) - len(built_now) - len(skipped), [w for w, _ in done])
            self.log.append(
                iteration, genomes[built_now], [w for w, _ in done], [n for _, n in done], rows
            )
            loss = losses if self.two_objective else losses.max(axis=1)
            return dataclasses.replace(base, loss=np.ascontiguousarray(loss))

        self._in_flight = collect
        return collect

    def _tally(self, rejected: int, walks: list[CandidateWalk]) -> None:
        counts = self.log.counts
        counts["rejected_2d"] += rejected
        for walk in walks:
            stage = walk.stage
            if stage == Stage.WALKED:
                counts["walks"] += 1
            elif stage == Stage.CACHED:
                counts["walk_cache_hits"] += 1
            elif stage == Stage.SEEDED:
                counts["walks_reused"] += 1
            elif stage == Stage.FAILED:
                counts["walk_failures"] += 1
            else:
                counts["rejected_build"] += 1

    def proposals(self, optimizer: Optimizer) -> Proposer | None:
        """Returns what proposes the optimizer's batches: SAIL's rounds on this evaluator's
        walk log (`workers.walk_sail`), or None (the optimizer's own variation)."""
        if self.sail is None:
            return None
        return self.sail.proposer(lambda: self.log, optimizer)  # type: ignore[arg-type]

    def prediction_map(self, optimizer: Optimizer) -> dict[str, np.ndarray]:
        """Returns a SAIL trial's prediction map (`workers.walk_sail.Sail.prediction_map`);
        {} for any other."""
        if self.sail is None:
            return {}
        return self.sail.prediction_map(self.log, optimizer)  # type: ignore[arg-type]

    def metrics(self) -> dict[str, float]:
        """Returns the walk log's running counts and best walks (`WalkLog.metrics`)."""
        return self.log.metrics()

    def state_dict(self) -> dict[str, np.ndarray]:
        """Returns the walk log (the state a resumed trial needs)."""
        state = self.log.state_dict() | {"walks.iteration_now": np.array(self._iteration)}
        if self.surrogate is not None:
            state |= self.surrogate.state_dict()
        return state

    def load_state_dict(self, state: Mapping[str, np.ndarray]) -> None:
        """Restores `state_dict`'s walk log (and the pre-screen's model, refitted)."""
        self.log = WalkLog.from_state(state)
        self._iteration = int(state["walks.iteration_now"])
        if self.surrogate is not None:
            self.surrogate.load_state_dict(state, self.log)

    def close(self) -> None:
        """Releases the walkers."""
        self.walkers.close()

    def __enter__(self) -> WalkingEvaluator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _by_floor(walk: CandidateWalk) -> dict[str, dict]:
    return {row["floor"]: row for row in walk.rows}
