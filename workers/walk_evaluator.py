"""Provides `WalkingEvaluator`: a walking trial's evaluator (fitness F_w, `sim.walk_fitness`).

A batch is evaluated as the path fitnesses are (the 2-D kernel gives every candidate its
foot path and descriptors), then screened: a candidate that fails the 2-D checks is
rejected at no walk's cost; the others are built as their LEGO legs and walked, here or on
the trial's evaluator actors (`ActorWalkers`), each candidate a task, so that an actor
that finishes early takes the next. A leg already walked in the trial is not walked
again: its rows are reused (the walk is deterministic). The evaluator keeps the trial's
walk log (`WalkLog`: every candidate it built, with its rows, the seconds it took and the
Ray node that walked it), which is its checkpointed state and, at the trial's end, its
`walks.parquet` and the walk map of what the trial kept.
"""

from __future__ import annotations

import dataclasses
import math
import socket
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from linkevo.sim import decode, simulate
from linkevo.sim.evaluating import evaluate
from linkevo.sim.evaluation import Evaluation
from linkevo.sim.genome import validate_genomes
from linkevo.sim.physical import physical_checks
from linkevo.sim.robot import WALK_SECONDS
from linkevo.sim.walk_fitness import (
    OBJECTIVE_FLOORS,
    WALK_ORDER,
    CandidateWalk,
    floor_losses,
    rejected_loss,
    walk_candidate,
)
from linkevo.sim.walk_map import COLUMNS, walk_map_frame
from linkevo.workers.evaluators import Bar, Pending
from linkevo.workers.seed_repertoire import Seed

if TYPE_CHECKING:
    import pandas as pd

FLOOR_FIELDS = ("status", "mean_distance_cm", "breaks", "reason", "bound_cm",
                "torque_p95_of_stall", "pin_force_p99_n", "seconds")  # fmt: skip
"""A walk-map row's figures, kept per floor in the walk log."""
LOG_COUNTERS = (
    "walks", "walk_cache_hits", "walks_reused", "rejected_2d", "rejected_build", "walk_failures",
    "walks_skipped",
)  # fmt: skip
"""The walk log's running counts, as the trial's metrics name them."""


@dataclass
class WalkLog:
    """Every candidate a walking trial built or walked, in the order it was told.

    Attributes:
        genome: (N, 56) each candidate.
        iteration: (N,) the iteration it was asked in (1 for the first batch).
        stage: (N,) its `sim.walk_fitness.STAGES` stage (never "rejected").
        key: (N,) its leg's key ("" when no leg was built).
        node: (N,) where it was built and walked (a Ray node id, or this host's name).
        compute_s: (N,) what its build and walks took there.
        floors: per floor of `WALK_ORDER`, its row's `FLOOR_FIELDS` as (N,) arrays (a
            cached candidate holds the rows of the walk it reused).
        counts: the running counts (`LOG_COUNTERS`), rejections by the 2-D checks
            included.
    """

    genome: np.ndarray
    iteration: np.ndarray
    stage: np.ndarray
    key: np.ndarray
    node: np.ndarray
    compute_s: np.ndarray
    floors: dict[str, dict[str, np.ndarray]]
    counts: dict[str, int]

    @classmethod
    def empty(cls) -> WalkLog:
        return cls(
            genome=np.zeros((0, 56)),
            iteration=np.zeros(0, np.int64),
            stage=np.zeros(0, "<U1"),
            key=np.zeros(0, "<U1"),
            node=np.zeros(0, "<U1"),
            compute_s=np.zeros(0),
            floors={f: _floor_columns([]) for f in WALK_ORDER},
            counts=dict.fromkeys(LOG_COUNTERS, 0),
        )

    def __len__(self) -> int:
        return len(self.stage)

    def append(self, iteration: int, genomes: np.ndarray, walks: list[CandidateWalk],
               nodes: list[str], rows: list[dict[str, dict]]) -> None:  # fmt: skip
        """Adds the built candidates of one batch: their genomes (K, 56), walks, nodes
        and rows by floor (a cached candidate's are the walk it reused)."""
        self.genome = np.concatenate([self.genome, genomes.reshape(-1, 56)])
        self.iteration = np.concatenate([self.iteration, np.full(len(walks), iteration)])
        self.stage = np.concatenate([self.stage, np.array([w.stage for w in walks], dtype=str)])
        self.key = np.concatenate([self.key, np.array([w.key for w in walks], dtype=str)])
        self.node = np.concatenate([self.node, np.array(nodes, dtype=str)])
        self.compute_s = np.concatenate([self.compute_s, [w.compute_s for w in walks]])
        for floor in WALK_ORDER:
            new = _floor_columns([r[floor] for r in rows])
            self.floors[floor] = {
                k: np.concatenate([v, new[k]]) for k, v in self.floors[floor].items()
            }

    def known(self) -> dict[str, dict[str, dict]]:
        """Returns the rows by floor of every leg walked so far on every floor it needs
        (a leg whose second floor was left out by its candidate's bar is not), by key."""
        skipped = np.zeros(len(self), dtype=bool)
        for columns in self.floors.values():
            skipped |= (columns["status"] == "not walked") & ~columns["breaks"]
        walked = np.flatnonzero((self.stage == "walked") & ~skipped)
        return {str(self.key[i]): self.rows(i) for i in walked}

    def rows(self, i: int) -> dict[str, dict]:
        """Returns candidate i's row per floor (`sim.walk_map.COLUMNS`, cell -1)."""
        out = {}
        for floor, columns in self.floors.items():
            values = {k: v[i].item() for k, v in columns.items()}
            out[floor] = {"cell": -1, "floor": floor, "leg": "LEGO build", **values}
        return out

    def metrics(self) -> dict[str, float]:
        """Returns the running counts and the best sound walk on each floor (cm credited,
        `sim.walk_fitness.credited_cm`; NaN before any)."""
        out = {k: float(v) for k, v in self.counts.items()}
        for floor in OBJECTIVE_FLOORS:
            columns = self.floors[floor]
            sound = (columns["status"] == "walked") & ~columns["breaks"]
            bound = columns["bound_cm"][sound]
            distance = columns["mean_distance_cm"][sound]
            credited = np.where(np.isfinite(bound), np.minimum(distance, bound), distance)
            credited = credited * WALK_SECONDS / columns["seconds"][sound]
            out[f"best_{floor}_cm"] = float(credited.max()) if credited.size else math.nan
        return out

    def state_dict(self) -> dict[str, np.ndarray]:
        """Returns the log as npz-safe arrays (`walks.` names)."""
        state = {
            "walks.genome": self.genome,
            "walks.iteration": self.iteration,
            "walks.stage": self.stage,
            "walks.key": self.key,
            "walks.node": self.node,
            "walks.compute_s": self.compute_s,
            "walks.counts": np.array([self.counts[k] for k in LOG_COUNTERS], np.int64),
        }
        for floor, columns in self.floors.items():
            state |= {f"walks.{floor}.{k}": v for k, v in columns.items()}
        return state

    @classmethod
    def from_state(cls, state: Mapping[str, np.ndarray]) -> WalkLog:
        """Returns the log `state_dict` saved (KeyError, ValueError when it is not one)."""
        floors = {f: {k: np.asarray(state[f"walks.{f}.{k}"]) for k in FLOOR_FIELDS}
                  for f in WALK_ORDER}  # fmt: skip
        counts = np.asarray(state["walks.counts"], np.int64)
        counts = np.pad(counts, (0, len(LOG_COUNTERS) - len(counts)))  # a log before a count
        log = cls(
            genome=np.asarray(state["walks.genome"], np.float64).reshape(-1, 56),
            iteration=np.asarray(state["walks.iteration"], np.int64),
            stage=np.asarray(state["walks.stage"]).astype(str),
            key=np.asarray(state["walks.key"]).astype(str),
            node=np.asarray(state["walks.node"]).astype(str),
            compute_s=np.asarray(state["walks.compute_s"], np.float64),
            floors=floors,
            counts=dict(zip(LOG_COUNTERS, counts.tolist(), strict=True)),
        )
        columns = [log.genome, log.iteration, log.stage, log.key, log.node, log.compute_s]
        sizes = {len(v) for v in columns} | {len(v) for c in floors.values() for v in c.values()}
        if len(sizes) != 1 or (counts < 0).any():
            raise ValueError(f"walk log columns of {sorted(sizes)} rows, counts {counts.tolist()}")
        return log

    def table(self) -> pd.DataFrame:
        """Returns the log as `walks.parquet`'s table: a row per candidate, its floors' figures
        as `<floor>_<field>` columns."""
        import pandas as pd

        columns: dict[str, object] = {
            "iteration": self.iteration,
            "stage": self.stage.astype(str),
            "leg_key": self.key.astype(str),
            "node": self.node.astype(str),
            "compute_s": self.compute_s,
        }
        for floor, figures in self.floors.items():
            columns |= {f"{floor}_{k}": v for k, v in figures.items()}
        frame = pd.DataFrame(columns)
        frame["genome"] = list(self.genome)
        return frame

    def walk_map(self, cells: np.ndarray, genomes: np.ndarray) -> pd.DataFrame:
        """Returns the walk map (`sim.walk_map.COLUMNS`) of kept individuals: cells (N,)
        and genomes (N, 56), a row per floor for each that the log built."""
        at = {g.tobytes(): i for i, g in enumerate(self.genome)}
        rows = []
        for cell, genome in zip(cells, genomes, strict=True):
            i = at.get(np.asarray(genome, np.float64).tobytes())
            if i is None:
                continue
            rows += [{**row, "cell": int(cell)} for row in self.rows(i).values()]
        return walk_map_frame(rows)[list(COLUMNS)]


def _floor_columns(rows: list[dict]) -> dict[str, np.ndarray]:
    def text(name: str) -> np.ndarray:  # as wide as the longest, npz-safe without pickle
        return np.array([r[name] for r in rows], dtype=str) if rows else np.zeros(0, "<U1")

    return {
        "status": text("status"),
        "mean_distance_cm": np.array([r["mean_distance_cm"] for r in rows], np.float64),
        "breaks": np.array([r["breaks"] for r in rows], bool),
        "reason": text("reason"),
        "bound_cm": np.array([r["bound_cm"] for r in rows], np.float64),
        "torque_p95_of_stall": np.array([r["torque_p95_of_stall"] for r in rows], np.float64),
        "pin_force_p99_n": np.array([r["pin_force_p99_n"] for r in rows], np.float64),
        "seconds": np.array([r["seconds"] for r in rows], np.float64),
    }


class Walkers(Protocol):
    """Where a batch's candidates are built and walked."""

    def walk(
        self, genomes: np.ndarray, mode: str, known: frozenset[str], bars: np.ndarray
    ) -> Iterator[tuple[CandidateWalk, str]]:
        """Yields each candidate's walk (`sim.walk_fitness.walk_candidate`, legs in
        `known` not walked, each with its bar (K,)) and where it ran, in order."""
        ...

    def close(self) -> None:
        """Releases what the walkers hold."""
        ...


class LocalWalkers:
    """Builds and walks every candidate in this process, one after another."""

    def walk(self, genomes: np.ndarray, mode: str, known: frozenset[str], bars: np.ndarray):
        host = socket.gethostname()
        for genome, bar in zip(genomes, bars, strict=True):
            yield walk_candidate(genome, mode, known, float(bar)), host

    def close(self) -> None:
        """Nothing to release."""


class WalkingEvaluator:
    """Evaluates a walking trial's batches (F_w, or F_w2 for a multi-objective approach).

    Args:
        mode: "paper" or "legacy".
        n_angles: crank angles of the 2-D evaluation.
        two_objective: return each floor's loss (B, 2) rather than the worse one (B,).
        walkers: where candidates are walked (`LocalWalkers`, `ActorWalkers`).
        surrogate: pre-screen the candidates with the learned walk model fitted on the
            trial's walks (`workers.walk_surrogate`); single-objective only.
    """

    def __init__(
        self,
        mode: str,
        n_angles: int,
        two_objective: bool,
        walkers: Walkers | None = None,
        surrogate: bool = False,
    ) -> None:
        self.mode = mode
        self.n_angles = n_angles
        self.two_objective = two_objective
        self.walkers = walkers or LocalWalkers()
        self.surrogate = None
        if surrogate:
            from linkevo.workers.walk_surrogate import WalkSurrogate

            self.surrogate = WalkSurrogate(mode)
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
        base = evaluate(genomes, "Fp", self.mode, n_angles=self.n_angles)
        batch = decode(genomes, self.mode)
        checks = physical_checks(batch, simulate(batch, self.n_angles))
        seeded = [self._seeded.get(g.tobytes()) for g in genomes]
        reused = np.array([r is not None for r in seeded])
        built = np.flatnonzero(checks.buildable & ~reused)
        bars = np.full(len(genomes), np.inf) if bar is None else bar(genomes, base)
        skipped = np.zeros(0, np.int64)
        if self.surrogate is not None:
            self.surrogate.refresh(self.log)
            worth = self.surrogate.worth_walking(genomes[built], bars[built])
            built, skipped = built[worth], built[~worth]
        known = self.log.known()
        walks = self.walkers.walk(genomes[built], self.mode, frozenset(known), bars[built])

        def collect() -> Evaluation:
            self._in_flight = None
            losses = np.repeat(rejected_loss(base.error, checks)[:, None], 2, axis=1)
            losses[skipped] = np.inf  # not walked: it enters no archive
            done = [(CandidateWalk("seeded", "", (), 0.0), "") for _ in np.flatnonzero(reused)]
            done += list(walks)
            rows = [seeded[i] for i in np.flatnonzero(reused)]
            built_now = np.concatenate([np.flatnonzero(reused), built]).astype(np.int64)
            for i, (walk, _) in zip(built_now, done, strict=True):
                if walk.stage == "seeded":
                    losses[i] = floor_losses("seeded", seeded[i])
                    continue
                by_floor = known[walk.key] if walk.stage == "cached" else _by_floor(walk)
                losses[i] = floor_losses(walk.stage, by_floor)
                rows.append(by_floor)
            self.log.counts["walks_skipped"] += len(skipped)
            self._tally(len(genomes) - len(built_now) - len(skipped), [w for w, _ in done])
            self.log.append(iteration, genomes[built_now], [w for w, _ in done],
                            [n for _, n in done], rows)  # fmt: skip
            loss = losses if self.two_objective else losses.max(axis=1)
            return dataclasses.replace(base, loss=np.ascontiguousarray(loss))

        self._in_flight = collect
        return collect

    def _tally(self, rejected: int, walks: list[CandidateWalk]) -> None:
        counts = self.log.counts
        counts["rejected_2d"] += rejected
        for walk in walks:
            stage = walk.stage
            if stage == "walked":
                counts["walks"] += 1
            elif stage == "cached":
                counts["walk_cache_hits"] += 1
            elif stage == "seeded":
                counts["walks_reused"] += 1
            elif stage == "failed":
                counts["walk_failures"] += 1
            else:
                counts["rejected_build"] += 1

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
