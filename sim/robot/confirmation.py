"""Provides `confirm_walk`: a walk the lean model gave, confirmed on the full model.

The walking search walks thousands of unusual legs on the lean model (`sim.robot.lean_model`),
which reduces each leg to what meets the floor; where that reduction fails, the search finds
the failure first. So what a walking trial reports as its best walker is walked again on the
full model (every beam a body, `sim.robot.full_model`) from `CONFIRM_REPEATS` hand-placed
starts per floor, Table I's protocol, and the two are set side by side: the full model's
credited distances (per 10 s, at most the level-body bound), whether it breaks, whether its
repeats disagree widely (a chaotic gait, `sim.robot.field_summary.chaotic`), and whether the
two models agree (`AGREEMENT`).
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass

from linkevo.sim.robot.field_summary import chaotic
from linkevo.sim.robot.hexapod import FLOORS, WALK_SECONDS, Robot
from linkevo.sim.robot.leg import Leg
from linkevo.sim.robot.walk_rows import FLOOR_ORDER
from linkevo.sim.robot.walking import WalkSettings, field_trials

CONFIRM_REPEATS = 5
"""Full-model walks per floor from hand-placed starts (Table I's five)."""
AGREEMENT = 0.3
"""The two models agree on a floor when their credited distances are within this share of
the full model's (both at least 10 cm, `NEAR_CM`, so walks on the spot compare alike), or
both break there."""
NEAR_CM = 10.0
"""The smallest distance a share of `AGREEMENT` is taken of."""


@dataclass(frozen=True)
class FloorCheck:
    """One floor of a confirmation.

    Attributes:
        floor: its name.
        lean_cm: the confirmed walk's credited distance (cm per 10 s), None where it broke.
        full_cm: (R,) the full model's credited distance per repeat (cm per 10 s; NaN where
            a repeat has none).
        full_breaks: most of the full model's repeats break.
        chaotic: the full model's repeats disagree widely.
    """

    floor: str
    lean_cm: float | None
    full_cm: tuple[float, ...]
    full_breaks: bool
    chaotic: bool

    @property
    def full_mean_cm(self) -> float:
        """The full model's mean credited distance (NaN when no repeat has one)."""
        finite = [v for v in self.full_cm if math.isfinite(v)]
        return statistics.fmean(finite) if finite else math.nan

    @property
    def agrees(self) -> bool:
        """Whether the models agree here (`AGREEMENT`)."""
        if self.lean_cm is None or self.full_breaks:
            return self.lean_cm is None and self.full_breaks
        full = self.full_mean_cm
        scale = max(abs(full), NEAR_CM)
        return math.isfinite(full) and abs(self.lean_cm - full) <= AGREEMENT * scale


@dataclass(frozen=True)
class Confirmation:
    """A walk confirmed on the full model, floor by floor (`FLOOR_ORDER`)."""

    floors: tuple[FloorCheck, ...]

    @property
    def agrees(self) -> bool:
        """The models agree on every floor."""
        return all(f.agrees for f in self.floors)

    @property
    def chaotic(self) -> bool:
        """The full model's repeats disagree widely on some floor."""
        return any(f.chaotic for f in self.floors)

    def as_dict(self) -> dict:
        """The confirmation as JSON-able values (`best_confirmed.json`)."""
        return {
            "agrees": self.agrees,
            "chaotic": self.chaotic,
            "repeats": len(self.floors[0].full_cm) if self.floors else 0,
            "floors": {
                f.floor: {
                    "lean_cm": None if f.lean_cm is None else round(f.lean_cm, 2),
                    "full_cm": [None if not math.isfinite(v) else round(v, 2) for v in f.full_cm],
                    "full_mean_cm": None
                    if not math.isfinite(f.full_mean_cm)
                    else round(f.full_mean_cm, 2),
                    "full_breaks": f.full_breaks,
                    "chaotic": f.chaotic,
                    "agrees": f.agrees,
                }
                for f in self.floors
            },
        }


def confirm_walk(
    leg: Leg,
    lean_cm: dict[str, float | None],
    robot: Robot | None = None,
    *,
    repeats: int = CONFIRM_REPEATS,
    seconds: float = WALK_SECONDS,
) -> Confirmation:
    """Returns a lean-model walk of `leg` confirmed on the full model.

    Args:
        lean_cm: the walk to confirm: its credited distance per floor (cm per 10 s), None
            where it broke.
        robot: the robot walked (default: the study's).
        repeats: full-model walks per floor, from hand-placed starts (`field_trials`).
        seconds: each walk's length.
    """
    checks = []
    for floor in FLOOR_ORDER:
        walks = field_trials(
            leg,
            FLOORS[floor],
            repeats=repeats,
            settings=WalkSettings(seconds=seconds, model="full"),
            robot=robot,
        )
        credited = tuple(
            min(w.distance_m, w.bound_m) * 100 * WALK_SECONDS / seconds
            if math.isfinite(w.distance_m) and not w.breaks
            else math.nan
            for w in walks
        )
        checks.append(
            FloorCheck(
                floor=floor,
                lean_cm=lean_cm.get(floor),
                full_cm=credited,
                full_breaks=2 * sum(w.breaks for w in walks) > len(walks),
                chaotic=chaotic(walks),
            )
        )
    return Confirmation(tuple(checks))
