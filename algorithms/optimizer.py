"""Provides the Optimizer protocol and the ask/tell machinery every approach shares."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Protocol

import numpy as np

from linkevo.algorithms.common_grid import COMMON_SPACE, CommonGrid
from linkevo.algorithms.individuals import Individuals
from linkevo.algorithms.mutation import check_initial_sigma, initial_sigma, mutate, n_sigmas
from linkevo.algorithms.rng_state import decode_rng, encode_rng
from linkevo.algorithms.scoring import QD_OFFSETS, WALKER_LOSS, scalar_loss
from linkevo.sim.linkage.evaluation import Evaluation
from linkevo.sim.linkage.genome import random_genomes
from linkevo.sim.study import DEFAULT_ANGLES, SINGLE_FITNESSES, evaluated_fitness

Proposer = Callable[[], tuple[np.ndarray, np.ndarray] | None]
"""Proposes an optimizer's next batch in place of its own variation: genomes (K, 56) and
their mutation strengths (K, S), or None to let the optimizer vary its parents (SAIL's
acquisition map, `workers.walk_sail`)."""


class Optimizer(Protocol):
    """What the trial loop drives: ask for genomes, tell their evaluation, report."""

    approach: str

    @property
    def eval_fitness(self) -> str:
        """The `sim.linkage.evaluating` fitness name the evaluator must use."""
        ...

    @property
    def evaluations(self) -> int:
        """Genomes told so far."""
        ...

    @property
    def iteration(self) -> int:
        """Completed ask/tell rounds (the initial population is round 1)."""
        ...

    def ask(self) -> np.ndarray:
        """Returns the next batch of genomes to evaluate, (B, 56)."""
        ...

    def propose_with(self, proposer: Proposer | None) -> None:
        """Takes later batches from `proposer` when it proposes one (`Proposer`)."""
        ...

    def tell(self, genomes: np.ndarray, evaluation: Evaluation) -> None:
        """Takes the evaluation of the genomes the last `ask` returned."""
        ...

    def metrics(self) -> dict[str, float]:
        """Returns evaluations, best_loss, mean_loss, coverage, qd_score (and extras)."""
        ...

    def bar(self, genomes: np.ndarray, evaluation: Evaluation) -> np.ndarray:
        """Returns (B,) for each asked genome the single-objective loss it must get below
        to change what the optimizer keeps or reports (inf: any loss might)."""
        ...

    def best(self) -> tuple[np.ndarray, float]:
        """Returns the best genome (56,) ever told and its single-objective loss."""
        ...

    def view(self) -> dict[str, np.ndarray]:
        """Returns the kept population or repertoire as named columns (1-D or (N, k))."""
        ...

    def settings(self) -> dict[str, object]:
        """Returns the JSON-able settings that define the optimizer."""
        ...

    def state_dict(self) -> dict[str, np.ndarray]:
        """Returns the whole search state as npz-safe numpy arrays."""
        ...

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restores a state from `state_dict`, so the search continues identically."""
        ...


class BaseOptimizer:
    """The ask/tell plumbing: the random initial batch, mutation, counters and state.

    Subclasses choose parents (`_parents`), keep survivors (`_survive`), report
    (`_summary`, `_columns`) and add their own state (`_state`, `_load_state`).

    Every approach keeps its best-ever individual (the lowest single-objective loss told
    so far, the first on ties), whether or not its survivors still hold it (the EA's do
    not): `best()` and the `best_loss` metric are that individual's.

    Args:
        fitness: "Fp" or "Fsl", the loss the study optimises.
        batch_size: genomes per ask (B); also the initial population.
        mode: "paper" or "legacy" (mutation and sigma count).
        seed: seeds the optimizer's own random stream.
        n_angles: crank angles of the evaluations (A, the foot path length).
        initial_sigma: fixed initial mutation strength; None draws it uniformly in [0, 1).
    """

    approach: str = ""
    multi_objective: bool = False
    random_batches: bool = False
    """Every batch is uniform random genomes (RANDOM), not only the first."""

    def __init__(
        self,
        *,
        fitness: str,
        batch_size: int,
        mode: str,
        seed: int,
        n_angles: int = DEFAULT_ANGLES,
        initial_sigma: float | None = None,
    ) -> None:
        if fitness not in SINGLE_FITNESSES:
            raise ValueError(f"unknown fitness {fitness!r}; allowed: {', '.join(SINGLE_FITNESSES)}")
        if (
            isinstance(batch_size, bool)
            or not isinstance(batch_size, int | np.integer)
            or batch_size < 1
        ):
            raise ValueError(f"batch_size must be a positive integer, got {batch_size!r}")
        n_sigmas(mode)
        check_initial_sigma(initial_sigma)
        self.fitness = fitness
        self.batch_size = int(batch_size)
        self.mode = mode
        self.seed = int(seed)
        self.n_angles = int(n_angles)
        self.initial_sigma = initial_sigma
        self.qd_offset = QD_OFFSETS[fitness]
        self._rng = np.random.default_rng(self.seed)
        self._evaluations = 0
        self._iteration = 0
        self._pending: tuple[np.ndarray, np.ndarray] | None = None
        self._best: Individuals | None = None
        self._common = CommonGrid()
        self._initial: np.ndarray | None = None
        self._proposer: Proposer | None = None

    @property
    def eval_fitness(self) -> str:
        """The `sim.linkage.evaluating` fitness name: the two-objective variant for NSGA-II."""
        return evaluated_fitness(self.fitness, self.multi_objective)

    @property
    def evaluations(self) -> int:
        """Genomes told so far."""
        return self._evaluations

    @property
    def iteration(self) -> int:
        """Completed ask/tell rounds (the initial population is round 1)."""
        return self._iteration

    def seed_with(self, genomes: np.ndarray) -> None:
        """Makes the first batch these genomes (K, 56) instead of random ones (a warm
        start from an earlier repertoire; its size is theirs)."""
        if self._iteration:
            raise RuntimeError("seed_with() before the first ask() only")
        self._initial = np.array(genomes, dtype=np.float64).reshape(-1, 56)

    def propose_with(self, proposer: Proposer | None) -> None:
        """Takes every batch after the first from `proposer` whenever it proposes one (its
        size is the proposal's), instead of mutating parents; None: the optimizer's own
        variation throughout. The proposer is not part of the state: give it again on
        resume."""
        self._proposer = proposer

    def ask(self) -> np.ndarray:
        """Returns the next batch, (B, 56): random (or seeded) genomes first, then the
        proposer's batch (`propose_with`) or mutated parents."""
        if self._pending is not None:
            raise RuntimeError("ask() called twice without tell(); tell the last batch first")
        proposed = None
        if self._iteration and self._proposer is not None and not self.random_batches:
            proposed = self._proposer()
        if proposed is not None:
            genomes, sigma = (np.array(a, dtype=np.float64) for a in proposed)
        elif self._iteration == 0 and self._initial is not None:
            genomes = self._initial
            sigma = initial_sigma(self._rng, len(genomes), self.mode, self.initial_sigma)
        elif self._iteration == 0 or self.random_batches:
            genomes = random_genomes(self._rng, self.batch_size)
            sigma = initial_sigma(self._rng, self.batch_size, self.mode, self.initial_sigma)
        else:
            genomes, sigma = mutate(*self._parents(), self._rng, self.mode)
        self._pending = (genomes, sigma)
        return genomes.copy()

    def tell(self, genomes: np.ndarray, evaluation: Evaluation) -> None:
        """Takes the evaluation of the last asked batch and selects survivors.

        Args:
            genomes: (B, 56), the genomes the last `ask` returned.
            evaluation: their `sim.evaluate(..., fitness=self.eval_fitness)` result.
        """
        if self._pending is None:
            raise RuntimeError("tell() called without a pending ask()")
        asked, sigma = self._pending
        if not np.array_equal(np.asarray(genomes), asked):
            raise ValueError("tell() needs exactly the genomes the last ask() returned")
        expected = (len(asked), 2) if self.multi_objective else (len(asked),)
        loss = np.asarray(evaluation.loss, dtype=np.float64)
        if loss.shape != expected:
            raise ValueError(
                f"{self.approach} needs losses of shape {expected} "
                f"(fitness {self.eval_fitness}), got {loss.shape}"
            )
        batch = Individuals(
            genome=asked,
            sigma=sigma,
            loss=loss,
            error=np.asarray(evaluation.error, dtype=np.int64),
            angle_error=np.asarray(evaluation.angle_error, dtype=np.float64),
            desc=np.asarray(self.descriptors_of(asked, evaluation), dtype=np.float64),
            foot_x=np.asarray(evaluation.foot_x, dtype=np.float64),
            foot_y=np.asarray(evaluation.foot_y, dtype=np.float64),
        )
        self._keep_best(batch)
        self._common.add(evaluation.descriptors[COMMON_SPACE], self._scalar(batch))
        self._survive(batch, initial=self._iteration == 0)
        self._evaluations += len(batch)
        self._iteration += 1
        self._pending = None

    def descriptors_of(self, genomes: np.ndarray, evaluation: Evaluation) -> np.ndarray:
        """Returns the continuous descriptors (B, D) kept with each told genome."""
        raise NotImplementedError

    def bar(self, genomes: np.ndarray, evaluation: Evaluation) -> np.ndarray:
        """Returns (B,) inf: a population's survivors depend on the whole batch, so any
        loss might change them (`Optimizer.bar`)."""
        return np.full(len(genomes), np.inf)

    def metrics(self) -> dict[str, float]:
        """Returns iteration, evaluations, best_loss (best-ever), mean_loss (of the kept
        individuals), coverage, qd_score (the approach's own grid), common_coverage and
        common_qd_score (every genome told, on the MAP-LIS grid: `CommonGrid`), ...."""
        best = np.nan if self._best is None else float(self._scalar(self._best)[0])
        return {
            "iteration": float(self._iteration),
            "evaluations": float(self._evaluations),
            "best_loss": best,
            **self._summary(),
            "common_coverage": self._common.coverage(),
            "common_qd_score": self._common.qd_score(self.qd_offset),
        }

    def _walkers(self, cell_losses) -> dict[str, float]:
        """Returns, for the walking fitness, how many cells (their best losses) hold a
        walker (`scoring.WALKER_LOSS`); nothing for the path fitnesses."""
        if self.fitness != "Fw":
            return {}
        return {"walkers": float(np.sum(np.asarray(cell_losses) <= WALKER_LOSS))}

    def best(self) -> tuple[np.ndarray, float]:
        """Returns the best-ever genome (56,) and its single-objective loss."""
        if self._best is None:
            raise RuntimeError("nothing told yet: tell() the first batch")
        return self._best.genome[0].copy(), float(self._scalar(self._best)[0])

    def _keep_best(self, batch: Individuals) -> None:
        loss = self._scalar(batch)
        i = int(np.argmin(np.where(np.isnan(loss), np.inf, loss)))
        if self._best is None or loss[i] < self._scalar(self._best)[0]:
            self._best = batch.take(slice(i, i + 1))

    def view(self) -> dict[str, np.ndarray]:
        """Returns the kept individuals as columns.

        Columns: cell (int64, -1 outside an archive), loss (single-objective), loss_0 and
        loss_1 (NSGA-II), error, angle_error, desc_0..desc_{D-1}, bin_0.. (archives only),
        genome (N, 56), sigma (N, S), foot_x and foot_y (N, A), plus approach extras.
        """
        kept = self._kept()
        if kept is None:
            return {}
        columns: dict[str, np.ndarray] = {"cell": np.full(len(kept), -1, dtype=np.int64)}
        columns["loss"] = self._scalar(kept)
        if kept.loss.ndim == 2:
            columns["loss_0"] = kept.loss[:, 0]
            columns["loss_1"] = kept.loss[:, 1]
        columns["error"] = kept.error
        columns["angle_error"] = kept.angle_error
        for d in range(kept.desc.shape[1]):
            columns[f"desc_{d}"] = kept.desc[:, d]
        columns |= self._columns()
        columns |= {
            "genome": kept.genome,
            "sigma": kept.sigma,
            "foot_x": kept.foot_x,
            "foot_y": kept.foot_y,
        }
        return columns

    def settings(self) -> dict[str, object]:
        """Returns the JSON-able settings that define this optimizer."""
        return {
            "approach": self.approach,
            "fitness": self.fitness,
            "eval_fitness": self.eval_fitness,
            "batch_size": self.batch_size,
            "mode": self.mode,
            "seed": self.seed,
            "n_angles": self.n_angles,
            "initial_sigma": self.initial_sigma,
            "qd_offset": self.qd_offset,
        }

    def state_dict(self) -> dict[str, np.ndarray]:
        """Returns the whole search state as npz-safe arrays (between iterations only)."""
        if self._pending is not None:
            raise RuntimeError("state_dict() between ask() and tell(); tell the batch first")
        return {
            "optimizer.settings": np.array(json.dumps(self.settings(), sort_keys=True)),
            "optimizer.rng": encode_rng(self._rng),
            "optimizer.evaluations": np.array(self._evaluations, dtype=np.int64),
            "optimizer.iteration": np.array(self._iteration, dtype=np.int64),
            **({} if self._best is None else self._best.to_state("best")),
            **self._common.state_dict(),
            **self._state(),
        }

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        """Restores `state_dict`'s output; the settings must match this optimizer's."""
        saved = json.loads(str(np.asarray(state["optimizer.settings"])[()]))
        mine = json.loads(json.dumps(self.settings(), sort_keys=True))
        if saved != mine:
            diff = sorted(k for k in set(saved) | set(mine) if saved.get(k) != mine.get(k))
            raise ValueError(
                "state was saved by a different optimizer; differing settings: "
                + ", ".join(f"{k} (saved {saved.get(k)!r}, here {mine.get(k)!r})" for k in diff)
            )
        self._rng = decode_rng(state["optimizer.rng"])
        evaluations = int(state["optimizer.evaluations"])
        iteration = int(state["optimizer.iteration"])
        if iteration < 0 or evaluations < iteration:
            raise ValueError(
                f"optimizer.iteration {iteration} and optimizer.evaluations {evaluations}: "
                "allowed: iteration >= 0 and evaluations >= iteration (a batch holds a genome)"
            )
        self._evaluations, self._iteration = evaluations, iteration
        self._pending = None
        self._load_state(state)
        self._common.load_state_dict(state)
        self._best = Individuals.from_state(state, "best") if "best.genome" in state else None

    def _scalar(self, kept: Individuals) -> np.ndarray:
        return scalar_loss(kept.loss, kept.error, kept.angle_error, self.fitness)

    def _parents(self) -> tuple[np.ndarray, np.ndarray]:
        """Returns the parents' genomes (B, 56) and mutation strengths (B, S)."""
        raise NotImplementedError

    def _survive(self, batch: Individuals, *, initial: bool) -> None:
        raise NotImplementedError

    def _kept(self) -> Individuals | None:
        raise NotImplementedError

    def _summary(self) -> dict[str, float]:
        raise NotImplementedError

    def _columns(self) -> dict[str, np.ndarray]:
        return {}

    def _state(self) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def _load_state(self, state: dict[str, np.ndarray]) -> None:
        raise NotImplementedError
