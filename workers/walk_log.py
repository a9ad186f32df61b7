"""Provides `WalkLog`: every candidate a walking trial built or walked, with its rows per
floor, the seconds and node it took, and the trial's running counts; a walking trial's
checkpointed state (`workers.walk_evaluator`) and, at its end, its `walks.parquet` and the
walk map of what it kept."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from linkevo.sim.robot.hexapod import WALK_SECONDS
from linkevo.sim.robot.walk_fitness import CandidateWalk
from linkevo.sim.robot.walk_rows import (
    COLUMNS,
    FLOOR_FIELDS,
    FLOOR_ORDER,
    LATER_COLUMNS,
    LEGO_BUILD,
    WALK_ORDER,
    Stage,
    Status,
    walk_map_frame,
)

if TYPE_CHECKING:
    import pandas as pd

LOG_COUNTERS = (
    "walks",
    "walk_cache_hits",
    "walks_reused",
    "rejected_2d",
    "rejected_build",
    "walk_failures",
    "walks_skipped",
)
"""The walk log's running counts, as the trial's metrics name them."""


@dataclass
class WalkLog:
    """Every candidate a walking trial built or walked, in the order it was told.

    Attributes:
        genome: (N, 56) each candidate.
        iteration: (N,) the iteration it was asked in (1 for the first batch).
        stage: (N,) its `sim.robot.walk_rows.Stage` (never rejected).
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

    def append(
        self,
        iteration: int,
        genomes: np.ndarray,
        walks: list[CandidateWalk],
        nodes: list[str],
        rows: list[dict[str, dict]],
    ) -> None:
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
            skipped |= (columns["status"] == Status.NOT_WALKED) & ~columns["breaks"]
        walked = np.flatnonzero((self.stage == Stage.WALKED) & ~skipped)
        return {str(self.key[i]): self.rows(i) for i in walked}

    def rows(self, i: int) -> dict[str, dict]:
        """Returns candidate i's row per floor (`sim.robot.walk_rows.COLUMNS`, cell -1)."""
        out = {}
        for floor, columns in self.floors.items():
            values = {k: v[i].item() for k, v in columns.items()}
            out[floor] = {"cell": -1, "floor": floor, "leg": LEGO_BUILD, **values}
        return out

    def metrics(self) -> dict[str, float]:
        """Returns the running counts and the best sound walk on each floor (cm credited,
        `sim.robot.walk_rows.credited_cm`; NaN before any)."""
        out = {k: float(v) for k, v in self.counts.items()}
        for floor in FLOOR_ORDER:
            columns = self.floors[floor]
            sound = (columns["status"] == Status.WALKED) & ~columns["breaks"]
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
        rows = len(np.asarray(state["walks.stage"]))

        def column(floor: str, name: str) -> np.ndarray:
            key = f"walks.{floor}.{name}"
            if key not in state and name in LATER_COLUMNS:
                return np.full(rows, np.nan)
            return np.asarray(state[key])

        floors = {f: {k: column(f, k) for k in FLOOR_FIELDS} for f in WALK_ORDER}
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
        """Returns the walk map (`sim.robot.walk_rows.COLUMNS`) of kept individuals: cells (N,)
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
        "foot_slip_mm_s": np.array([r["foot_slip_mm_s"] for r in rows], np.float64),
        "seconds": np.array([r["seconds"] for r in rows], np.float64),
    }
