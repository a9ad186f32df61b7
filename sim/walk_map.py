"""Provides `walk_cells`: a batch of repertoire cells walked on the simulated robot, one
walk per cell and floor (the walk map's protocol).

A walk-map walk is the Table I protocol's walk (`sim.walk.walk` on the lean model) once,
from the unperturbed start, instead of five times from hand-placed starts: repeats of one
linkage agree within a centimetre or two except where a robot breaks (docs/walking.md), so
one walk ranks the cells of a map as the five do, at a fifth of the cost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from linkevo.sim.leg import LegError, leg_from_genome
from linkevo.sim.robot import FLOORS
from linkevo.sim.walk import WalkSettings, walk

WALK_SECONDS = 10.0
"""A walk-map walk's length, as Table I's."""
COLUMNS = (
    "cell",
    "floor",
    "status",
    "mean_distance_cm",
    "breaks",
    "reason",
    "leg",
    "bound_cm",
    "torque_p95_of_stall",
    "pin_force_p99_n",
    "seconds",
)
"""A walk-map row, per cell and floor. status: "walked", "not buildable" (no whole-module
rounding of the linkage turns; walked only with `as_evolved`), or "failed" (the reason is
the error)."""


@dataclass(frozen=True)
class CellBatch:
    """Cells to walk: their flat cell numbers (N,) and genomes (N, 56), in one mode."""

    cells: np.ndarray
    genomes: np.ndarray
    mode: str
    floors: tuple[str, ...]
    as_evolved: bool = False
    seconds: float = WALK_SECONDS


def walk_cells(batch: CellBatch) -> list[dict]:
    """Returns a row (`COLUMNS`) per cell and floor of the batch.

    A cell is walked as its LEGO build; when no whole-module rounding of it turns it is
    "not buildable" and walked as evolved only with `batch.as_evolved`. A linkage that
    does not turn a full turn breaks without being walked. Any other error is recorded as
    the cell's "failed" row with its message, and the batch goes on.
    """
    rows = []
    settings = WalkSettings(seconds=batch.seconds)
    for cell, genome in zip(batch.cells, batch.genomes, strict=True):
        base = {"cell": int(cell), "seconds": float(batch.seconds)}
        try:
            leg = leg_from_genome(genome, batch.mode)
        except LegError as exc:
            rows += [_row(base, f, "walked", breaks=True, reason=str(exc)) for f in batch.floors]
            continue
        except Exception as exc:  # recorded per cell, the batch goes on
            rows += [_row(base, f, "failed", reason=_error(exc)) for f in batch.floors]
            continue
        if not leg.built and not batch.as_evolved:
            rows += [_row(base, f, "not buildable", reason=leg.note) for f in batch.floors]
            continue
        kind = "LEGO build" if leg.built else "as evolved"
        for floor in batch.floors:
            try:
                w = walk(leg, FLOORS[floor], settings=settings)
            except Exception as exc:  # recorded per cell and floor
                rows.append(_row(base, floor, "failed", reason=_error(exc), leg=kind))
                continue
            rows.append(
                _row(
                    base,
                    floor,
                    "walked",
                    distance=w.distance_m * 100,
                    breaks=w.breaks,
                    reason=w.reason,
                    leg=kind,
                    bound=w.bound_m * 100,
                    torque=w.torque_p95,
                    pins=w.pin_force_n[2],
                )
            )
    return rows


def _row(
    base: dict,
    floor: str,
    status: str,
    *,
    distance: float = math.nan,
    breaks: bool = False,
    reason: str = "",
    leg: str = "",
    bound: float = math.nan,
    torque: float = math.nan,
    pins: float = math.nan,
) -> dict:
    return {
        **base,
        "floor": floor,
        "status": status,
        "mean_distance_cm": float(distance),
        "breaks": bool(breaks),
        "reason": reason,
        "leg": leg,
        "bound_cm": float(bound),
        "torque_p95_of_stall": float(torque),
        "pin_force_p99_n": float(pins),
    }


def _error(exc: Exception) -> str:
    return f"{type(exc).__name__}: {exc}"
