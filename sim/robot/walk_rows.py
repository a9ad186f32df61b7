"""Provides the walk's vocabulary, without MuJoCo: a walk row (one leg's walk on one floor,
as the walk map, the walking fitness, the walk log, the walk model, `pull` and Table I
read it), its statuses, a walking candidate's stages, the floors' order and the distance
a walk is credited.

A walk row (`WalkRow`, `COLUMNS`) is a dict of plain values so that it goes into a table,
a JSON document or an npz file as it is; its status and a candidate's stage are `StrEnum`
members, equal to (and written as) their text.
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import TYPE_CHECKING, TypedDict, get_type_hints

from linkevo.sim.robot.hexapod import CARPET, FLAT, WALK_SECONDS

if TYPE_CHECKING:
    import pandas as pd

    from linkevo.sim.robot.walking import Walk

FLOOR_ORDER: tuple[str, str] = (FLAT, CARPET)
"""The floors in the order tables, figures and F_w2's two objectives take them (loss_0 flat,
loss_1 carpet)."""
WALK_ORDER: tuple[str, str] = (CARPET, FLAT)
"""The order the walking fitness walks a candidate's floors: carpet first, where legs break
most."""
WALKER_CM = 50.0
"""A walker: a leg that walks at least this far (cm, 10 s) on both floors without breaking."""


class Status(StrEnum):
    """What became of a walk row's walk."""

    WALKED = "walked"
    """Walked on the physics (it may break)."""
    NOT_BUILDABLE = "not buildable"
    """No whole-module rounding of the linkage turns (walked only as evolved, on request)."""
    NOT_WALKED = "not walked"
    """The walking fitness walks no second floor for a leg that broke, or lost, on the first."""
    FAILED = "failed"
    """The build or the walk raised; the reason is the error."""


STATUSES = frozenset(Status)
"""Every status a walk row may have."""


class Stage(StrEnum):
    """Where a walking candidate's evaluation ended (`sim.robot.walk_fitness`)."""

    WALKED = "walked"
    """Walked on the physics."""
    CACHED = "cached"
    """Its leg was walked before in the trial: its rows are reused."""
    SEEDED = "seeded"
    """A warm start's cell, told with its walk map's rows."""
    REJECTED = "rejected"
    """Rejected by the 2-D checks (never built)."""
    NO_LEGO_BUILD = "no_lego_build"
    """No whole-module rounding turns."""
    NO_TURN = "no_turn"
    """The LEGO build does not turn a full turn."""
    FAILED = "failed"
    """The build or a walk raised."""


STAGES: tuple[str, ...] = tuple(Stage)
"""Every stage, in `Stage`'s order."""
TOLD_STAGES = frozenset({Stage.WALKED, Stage.CACHED, Stage.SEEDED})
"""The stages whose rows are a walk (the others' losses are the tiers below a walk)."""


class WalkRow(TypedDict):
    """One leg's walk on one floor (`COLUMNS`): the cell (-1 before a cell takes it), the
    floor, its `Status`, the mean distance (cm) in `seconds`, whether it breaks and why,
    the leg ("LEGO build" or "as evolved"), the level-body no-slip bound (cm), the motors'
    95th-percentile torque over stall, the 99th-percentile pin force (N) and the feet's
    mean slip while down (mm/s, `sim.robot.walking.Walk.foot_slip_mm_s`)."""

    cell: int
    floor: str
    status: str
    mean_distance_cm: float
    breaks: bool
    reason: str
    leg: str
    bound_cm: float
    torque_p95_of_stall: float
    pin_force_p99_n: float
    foot_slip_mm_s: float
    seconds: float


COLUMNS: tuple[str, ...] = tuple(WalkRow.__annotations__)
"""A walk row's columns, in order (a walk map's table, before the cells' bins)."""
FLOOR_FIELDS: tuple[str, ...] = tuple(c for c in COLUMNS if c not in ("cell", "floor", "leg"))
"""A walk row's figures, kept per floor where a table holds a candidate's floors side by
side (the walk log, `walks.parquet`'s `<floor>_<field>` columns)."""
LATER_COLUMNS: tuple[str, ...] = ("foot_slip_mm_s",)
"""Columns a walk table written before them lacks: read as NaN (unknown)."""
SLIDING_SHARE = 0.5
"""A walk whose feet slip, while down, at more than this share of the body's speed owes
most of its distance to sliding, not stepping (`slide_share`): flagged where a user sees
it (`linkevo pull`, the explorer, the report)."""
LEGO_BUILD, AS_EVOLVED = "LEGO build", "as evolved"
"""A walk row's `leg`: the LEGO build, or the linkage as evolved where no build turns."""


def map_row(
    base: dict,
    floor: str,
    status: Status,
    *,
    distance: float = math.nan,
    breaks: bool = False,
    reason: str = "",
    leg: str = "",
    bound: float = math.nan,
    torque: float = math.nan,
    pins: float = math.nan,
    slip: float = math.nan,
) -> WalkRow:
    """Returns a row from `base` (its cell and seconds) and the figures."""
    return {  # type: ignore[return-value]
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
        "foot_slip_mm_s": float(slip),
    }


def walked_row(base: dict, floor: str, w: Walk, leg: str) -> WalkRow:
    """Returns the row of a walk on `floor` (`leg`: `LEGO_BUILD` or `AS_EVOLVED`)."""
    return map_row(
        base,
        floor,
        Status.WALKED,
        distance=w.distance_m * 100,
        breaks=w.breaks,
        reason=w.reason,
        leg=leg,
        bound=w.bound_m * 100,
        torque=w.torque_p95,
        pins=w.pin_force_n[2],
        slip=w.foot_slip_mm_s,
    )


def error_text(exc: Exception) -> str:
    """The row's reason for an error: its type and message."""
    return f"{type(exc).__name__}: {exc}"


def credited_cm(row: dict) -> float:
    """Returns the distance a row's walk is credited, in cm per the study's 10 s: what it
    walked in its `seconds`, at most its level-body no-slip bound (`bound_cm`)."""
    distance, bound = row["mean_distance_cm"], row["bound_cm"]
    walked = min(distance, bound) if math.isfinite(bound) else distance
    return walked * WALK_SECONDS / row["seconds"]


def slide_share(row: dict) -> float:
    """Returns how fast a row's feet slip while down, as a share of the body's speed (NaN
    where unknown or the robot did not move forwards): 0 for a walker whose feet stand
    while they push, about 1 for a robot that skates on its feet."""
    distance, slip = row["mean_distance_cm"], row.get("foot_slip_mm_s", math.nan)
    if not (math.isfinite(distance) and math.isfinite(slip)) or distance <= 0:
        return math.nan
    return slip / (distance * 10.0 / row["seconds"])


def beyond_bound_share(row: dict) -> float:
    """Returns how far a row's walk goes beyond its level-body no-slip bound, as a share of
    the bound (0 within it; NaN where unknown): what stepping cannot explain."""
    distance, bound = row["mean_distance_cm"], row["bound_cm"]
    if not (math.isfinite(distance) and math.isfinite(bound)) or bound <= 0:
        return math.nan
    return max(distance / bound - 1.0, 0.0)


def walk_map_frame(rows: list[WalkRow]) -> pd.DataFrame:
    """Returns walk rows as a pandas table with the columns' own dtypes (int64 cell, bool
    breaks, float64 figures), also when there are none."""
    import pandas as pd

    frame = pd.DataFrame(rows, columns=list(COLUMNS))
    dtypes = {int: "int64", str: "str", bool: "bool", float: "float64"}
    return frame.astype({name: dtypes[kind] for name, kind in get_type_hints(WalkRow).items()})
