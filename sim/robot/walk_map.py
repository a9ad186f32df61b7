"""Provides the walk map's two steps: `build_cells` (each repertoire cell's leg, or the row
that says why it is not walked) and `walk_legs` (each distinct leg walked once per floor),
and `walk_cells`, the two in one process.

A walk-map walk is the Table I protocol's walk (`sim.robot.walking.walk` on the lean model) once,
from the unperturbed start, instead of five times from hand-placed starts, at twice the
physics step and with the sparse constraint Jacobian (the same walk to rounding). Repeats
of one linkage agree within a centimetre or two except where a robot breaks, and the
coarser step moves a distance by a few millimetres in the median (docs/walking.md), so one
such walk ranks the cells of a map as Table I's five do, at an eighth of the cost.
Neighbouring cells often round to the same LEGO build (the 7,514 walked cells of a study
repertoire have 5,202 distinct legs), and the walk is deterministic, so each distinct leg
(`LegRecipe.key`) is walked once and its rows are every such cell's.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from linkevo.sim.robot.hexapod import FLOORS, WALK_SECONDS, Robot
from linkevo.sim.robot.leg import LegError, LegRecipe, leg_recipe
from linkevo.sim.robot.walk_rows import (
    AS_EVOLVED,
    LEGO_BUILD,
    Status,
    WalkRow,
    error_text,
    map_row,
    walked_row,
)
from linkevo.sim.robot.walking import WalkSettings, walk

WALK_MAP_STEP_S = 0.004
"""A walk-map walk's physics step, twice Table I's: it ranks cells as Table I's walks do
(docs/walking.md) at about 60 % of the cost; a walk that blows up is walked again at half
the step, as every walk is."""


@dataclass(frozen=True)
class CellBatch:
    """Cells to walk: their flat cell numbers (N,) and genomes (N, 56), in one mode."""

    cells: np.ndarray
    genomes: np.ndarray
    mode: str
    floors: tuple[str, ...]
    as_evolved: bool = False
    seconds: float = WALK_SECONDS


@dataclass(frozen=True)
class BuiltCell:
    """A cell after its leg's build: the `recipe` of the leg to walk on `floors`, or, when
    it is not walked, its rows (it breaks without walking, is not buildable, or failed)."""

    cell: int
    floors: tuple[str, ...]
    recipe: LegRecipe | None = None
    rows: list[WalkRow] = field(default_factory=list)


@dataclass(frozen=True)
class LegBatch:
    """Distinct legs to walk on the same floors: their recipes, by the caller's name for
    each."""

    recipes: dict[str, LegRecipe]
    floors: tuple[str, ...]
    seconds: float = WALK_SECONDS
    robot: Robot = field(default_factory=Robot)


def walk_map_settings(seconds: float = WALK_SECONDS) -> WalkSettings:
    """Returns how a walk-map walk is simulated: the lean model at `WALK_MAP_STEP_S`, with
    the sparse constraint Jacobian."""
    return WalkSettings(seconds=seconds, timestep=WALK_MAP_STEP_S, sparse=True)


def build_cells(batch: CellBatch) -> list[BuiltCell]:
    """Returns each cell of the batch built: its leg's recipe, or its rows.

    A cell is walked as its LEGO build; when no whole-module rounding of it turns it is
    "not buildable" and walked as evolved only with `batch.as_evolved`. A linkage that
    does not turn a full turn breaks without being walked. Any other error is recorded as
    the cell's "failed" row with its message, and the batch goes on.
    """
    out = []
    for cell, genome in zip(batch.cells, batch.genomes, strict=True):
        base = {"cell": int(cell), "seconds": float(batch.seconds)}
        recipe, rows = None, []
        try:
            recipe = leg_recipe(genome, batch.mode)
        except LegError as exc:
            rows = [
                map_row(base, f, Status.WALKED, breaks=True, reason=str(exc)) for f in batch.floors
            ]
        except Exception as exc:  # recorded per cell, the batch goes on
            rows = [map_row(base, f, Status.FAILED, reason=error_text(exc)) for f in batch.floors]
        if recipe is not None and recipe.note and not batch.as_evolved:
            rows = [
                map_row(base, f, Status.NOT_BUILDABLE, reason=recipe.note) for f in batch.floors
            ]
            recipe = None
        out.append(BuiltCell(int(cell), batch.floors, recipe=recipe, rows=rows))
    return out


def walk_legs(batch: LegBatch) -> dict[str, list[WalkRow]]:
    """Returns each leg's rows (one per floor, `cell` -1 until a cell takes them), by name.

    A walk that raises is recorded as that floor's "failed" row with the error.
    """
    settings = walk_map_settings(batch.seconds)
    out = {}
    for key, recipe in batch.recipes.items():
        base = {"cell": -1, "seconds": float(batch.seconds)}
        kind = AS_EVOLVED if recipe.note else LEGO_BUILD
        try:
            leg = recipe.leg()
        except Exception as exc:  # recorded per leg, the batch goes on
            out[key] = [
                map_row(base, f, Status.FAILED, reason=error_text(exc), leg=kind)
                for f in batch.floors
            ]
            continue
        rows = []
        for floor in batch.floors:
            try:
                w = walk(leg, FLOORS[floor], settings=settings, robot=batch.robot)
            except Exception as exc:  # recorded per leg and floor
                rows.append(map_row(base, floor, Status.FAILED, reason=error_text(exc), leg=kind))
                continue
            rows.append(walked_row(base, floor, w, kind))
        out[key] = rows
    return out


@dataclass(frozen=True)
class LegToWalk:
    """A distinct leg to walk once on `floors`, and the cells whose rows its walk is."""

    recipe: LegRecipe
    floors: tuple[str, ...]
    cells: list[int]


def group_legs(built: list[BuiltCell]) -> list[LegToWalk]:
    """Returns the built cells' distinct legs (by recipe key and floors), each with its
    cells."""
    groups: dict[tuple[str, tuple[str, ...]], LegToWalk] = {}
    for b in built:
        if b.recipe is not None:
            key = (b.recipe.key, b.floors)
            groups.setdefault(key, LegToWalk(b.recipe, b.floors, [])).cells.append(b.cell)
    return list(groups.values())


def rows_for_cells(rows: list[WalkRow], cells: list[int]) -> list[WalkRow]:
    """Returns a leg's rows (`walk_legs`) as every cell's that builds it."""
    return [{**row, "cell": int(cell)} for cell in cells for row in rows]


def leg_batches(
    legs: list[LegToWalk], seconds: float, per_task: int, robot: Robot
) -> list[LegBatch]:
    """Returns the walk tasks of distinct legs (`group_legs`), `per_task` legs on the same
    floors each, walked on `robot`; a leg is named by its index in
    `legs`."""
    by_floors: dict[tuple[str, ...], list[int]] = {}
    for i, leg in enumerate(legs):
        by_floors.setdefault(leg.floors, []).append(i)
    out = []
    for floors, index in by_floors.items():
        for start in range(0, len(index), per_task):
            named = {str(i): legs[i].recipe for i in index[start : start + per_task]}
            out.append(LegBatch(named, floors, seconds, robot))
    return out


def walk_rows(
    run: Callable[[Callable[[Any], Any], list], Iterable[Any]],
    batches: list[CellBatch],
    seconds: float,
    legs_per_task: int,
    robot: Robot | None = None,
) -> Iterator[tuple[int, list[WalkRow]]]:
    """Yields, as each task ends, how many cells it built and the rows it settled: while
    the legs are built, the rows of the cells that are not walked; then each distinct
    leg's walks as the rows of every cell that builds it.

    Args:
        run: runs a function over items and yields each result as it ends (here, or as
            Ray tasks: `orchestrator.repertoire_walks`).
        batches: the cells.
        seconds: each walk's length.
        legs_per_task: distinct legs per walk task.
        robot: the robot walked (default: the study's robot).
    """
    built = []
    for cells in run(build_cells, batches):
        yield len(cells), [r for b in cells for r in b.rows]
        built += [b for b in cells if b.recipe is not None]
    legs = group_legs(built)
    tasks = leg_batches(legs, seconds, legs_per_task, robot or Robot())
    for walked in run(walk_legs, tasks):
        for name, leg_rows in walked.items():
            yield 0, rows_for_cells(leg_rows, legs[int(name)].cells)


def walk_cells(batch: CellBatch, robot: Robot | None = None) -> list[WalkRow]:
    """Returns a row (`COLUMNS`) per cell and floor of the batch, walked in this process
    (`walk_rows` with every leg in one task) on `robot` (default: the study's)."""
    legs = max(1, len(batch.cells))
    rows = [r for _, part in walk_rows(map, [batch], batch.seconds, legs, robot) for r in part]
    cell_order = {int(c): i for i, c in enumerate(batch.cells)}
    return sorted(rows, key=lambda r: (cell_order[r["cell"]], batch.floors.index(r["floor"])))
