"""Provides the walking fitness F_w: a linkage's loss from its LEGO leg walked on the robot.

A candidate that passes the study's 2-D physical checks (`sim.linkage.physical`) is built as its
whole-module LEGO leg (`sim.robot.leg.recipe_and_leg`: the build `linkevo pull` makes) and walked
with the walk map's walk (`sim.robot.walk_map.walk_map_settings`) for `SEARCH_SECONDS`, stopped
at its break (`WalkSettings.stop_at_break`), on carpet and then on flat. Its loss on a floor
is minus the distance walked there, in cm per the study's 10 s (`credited_cm`); F_w is the
worse floor's, since a builder wants a leg that walks on both, and its two-objective
variant F_w2 (NSGA-II) keeps the floors apart (`FLOOR_ORDER`). A leg that breaks on
carpet is not walked on flat: it is broken whatever flat does, so its flat loss is its
carpet loss.

What does not walk soundly still gets a loss a search can climb, in tiers that never
overlap (a sound walk's loss is under 1000: no robot walks 10 m in 10 s):

- walked, no break: -distance;
- walked, broke (or diverged): `BROKEN_LOSS` - the distance walked until it stopped (0 if
  it diverged);
- no LEGO build turns, no real parts build it, the build does not turn a full turn, or
  the build failed: `NO_LEG_LOSS`;
- fails the 2-D checks (never built): `REJECTED_LOSS` + failed crank angles + toggle
  passages + 1 if a beam stretches.

A broken robot that walked further before it stopped ranks above one that stopped sooner;
a rejected linkage that assembles at more crank angles, with fewer toggles, ranks above
one that assembles at fewer: each tier points towards the next.

A walk is credited at most its level-body no-slip bound (`credited_cm`; `Walk.bound_m`:
twice the stance stroke per crank turn, over the turns made). A robot walks further only
by sliding or hopping forwards, which the simulated contacts give some legs and a LEGO
robot on a real floor does not: a search rewarded for it finds such legs first (an
uncapped MAP-LIS trial's best walker went 286 cm on carpet against a bound of 179).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Container
from dataclasses import dataclass

import numpy as np

from linkevo.sim.linkage.physical import BUILDABLE_STRETCH, PhysicalChecks
from linkevo.sim.robot.hexapod import FLOORS, Robot
from linkevo.sim.robot.leg import LegError, recipe_and_leg
from linkevo.sim.robot.walk_map import walk_map_settings
from linkevo.sim.robot.walk_rows import (
    FLOOR_ORDER,
    LEGO_BUILD,
    TOLD_STAGES,
    WALK_ORDER,
    Stage,
    Status,
    WalkRow,
    credited_cm,
    error_text,
    map_row,
    walked_row,
)
from linkevo.sim.robot.walking import WalkSettings, walk

BROKEN_LOSS = 1000.0
"""A floor's loss when the robot breaks there, less the distance walked until it stopped."""
NO_LEG_LOSS = 2000.0
"""A floor's loss when the candidate has no LEGO leg that turns (or its build failed)."""
REJECTED_LOSS = 3000.0
"""A floor's loss when the candidate fails the 2-D checks, plus its grade (`rejected_loss`)."""
SOUND_BELOW = BROKEN_LOSS / 2
"""An F_w loss below this is a sound walk's (no robot walks 5 m in 10 s, backwards or
before it breaks); at or above it the robot broke or was never walked."""
SEARCH_SECONDS = 5.0
"""A search walk's length (after the half-second settle). Against the Table I protocol on
24 buildable cells of a study repertoire (`benchmarks/walkmap_fidelity.py`), its distance
scaled to 10 s ranks the cells that do not break as the protocol does (Spearman 0.979 on
flat, 0.993 on carpet; the 10-s walk-map walk 0.998 and 1.000), at 58 % of the 10-s walk's
cost."""


def search_walk_settings(seconds: float = SEARCH_SECONDS) -> WalkSettings:
    """Returns the walking fitness's walk: the walk map's, `seconds` long, stopped at its
    break."""
    return dataclasses.replace(walk_map_settings(seconds), stop_at_break=True)


@dataclass(frozen=True)
class CandidateWalk:
    """What walking one candidate gave.

    Attributes:
        stage: its `Stage` (walked, no LEGO build, no turn or failed here).
        key: the leg's key (`LegRecipe.key`; "" when no leg was built).
        rows: a walk row (cell -1) per floor of `WALK_ORDER`.
        compute_s: the time the build and the walks took.
    """

    stage: Stage
    key: str
    rows: tuple[WalkRow, ...]
    compute_s: float


def walk_candidate(
    genome: np.ndarray,
    mode: str,
    known: Container[str] = (),
    bar: float = math.inf,
    seconds: float = SEARCH_SECONDS,
    robot: Robot | None = None,
    searched: np.ndarray | None = None,
) -> CandidateWalk:
    """Builds a candidate's LEGO leg and walks it: carpet, then flat unless it broke there
    or its carpet loss alone is at or above `bar`.

    Args:
        genome: (56,) one candidate that passed the 2-D checks.
        mode: "paper" or "legacy".
        known: keys of legs already walked in the trial: such a leg is not walked again
            (stage "cached", no rows: the caller has them).
        bar: the F_w loss the candidate must get below to change what the search keeps
            (`algorithms.Optimizer.bar`): F_w is the worse floor's loss, so once the first
            floor's is at or above it the second cannot matter and is not walked.
        seconds: each walk's length.
        robot: the robot walked (default: the study's robot).
        searched: (15,) the build's lengths where the caller found them for its whole
            batch (`sim.robot.builds.build_lengths`), so the leg is not searched again.
    """
    start = time.perf_counter()
    base = {"cell": -1, "seconds": float(seconds)}

    def done(stage: Stage, key: str, rows: list[WalkRow]) -> CandidateWalk:
        return CandidateWalk(stage, key, tuple(rows), time.perf_counter() - start)

    try:
        recipe, leg = recipe_and_leg(genome, mode, searched)
    except LegError as exc:
        return done(
            Stage.NO_TURN,
            "",
            [map_row(base, f, Status.WALKED, breaks=True, reason=str(exc)) for f in WALK_ORDER],
        )
    except Exception as exc:  # recorded per candidate, the batch goes on
        return done(
            Stage.FAILED,
            "",
            [map_row(base, f, Status.FAILED, reason=error_text(exc)) for f in WALK_ORDER],
        )
    if recipe.note:
        rows = [map_row(base, f, Status.NOT_BUILDABLE, reason=recipe.note) for f in WALK_ORDER]
        return done(Stage.NO_LEGO_BUILD, recipe.key, rows)
    if recipe.key in known:
        return done(Stage.CACHED, recipe.key, [])
    settings = search_walk_settings(seconds)
    rows = []
    for floor in WALK_ORDER:
        if rows and rows[-1]["breaks"]:
            reason = f"not walked: it breaks on {rows[-1]['floor']}"
            rows.append(
                map_row(base, floor, Status.NOT_WALKED, breaks=True, reason=reason, leg=LEGO_BUILD)
            )
            continue
        if rows and -credited_cm(rows[-1]) >= bar:
            reason = f"not walked: {rows[-1]['floor']} alone keeps it out of the search"
            rows.append(map_row(base, floor, Status.NOT_WALKED, reason=reason, leg=LEGO_BUILD))
            continue
        try:
            w = walk(leg, FLOORS[floor], settings=settings, robot=robot)
        except Exception as exc:  # recorded per candidate, the batch goes on
            failed = [map_row(base, f, Status.FAILED, reason=error_text(exc)) for f in WALK_ORDER]
            return done(Stage.FAILED, recipe.key, failed)
        rows.append(walked_row(base, floor, w, LEGO_BUILD))
    return done(Stage.WALKED, recipe.key, rows)


def floor_losses(stage: Stage, rows: dict[str, WalkRow]) -> np.ndarray:
    """Returns (2,) a built candidate's loss on each of `FLOOR_ORDER` (F_w2's objectives).

    Args:
        stage: the candidate's stage (any but "rejected").
        rows: its row per floor (a walked or cached candidate's walk-map rows).
    """
    if stage not in TOLD_STAGES:
        return np.full(2, NO_LEG_LOSS)
    losses = {}
    for floor, row in rows.items():
        if row["status"] != Status.WALKED:
            continue
        distance = credited_cm(row)
        if row["breaks"]:
            losses[floor] = BROKEN_LOSS - (distance if math.isfinite(distance) else 0.0)
        else:
            losses[floor] = -distance
    worst = max(losses.values())  # a floor not walked takes the floor where it broke
    return np.array([losses.get(f, worst) for f in FLOOR_ORDER])


def rejected_loss(failed_angles: np.ndarray, checks: PhysicalChecks) -> np.ndarray:
    """Returns (N,) the loss of linkages that fail the 2-D checks: `REJECTED_LOSS` plus their
    failed crank angles (N,), toggle passages, and 1 when a beam stretches."""
    stretch = np.nan_to_num(checks.max_stretch, nan=np.inf) > BUILDABLE_STRETCH
    return REJECTED_LOSS + failed_angles + checks.toggle_passages + stretch.astype(float)
