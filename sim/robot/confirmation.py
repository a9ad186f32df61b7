"""Provides `confirm_walk`: a walk the lean model gave, confirmed on the full model.

The walking search walks thousands of unusual legs on the lean model (`sim.robot.lean_model`),
which reduces each leg to what meets the floor; where that reduction fails, the search finds
the failure first. So what a walking trial reports as its best walker is walked again on the
full model (every beam a body, `sim.robot.full_model`) from `CONFIRM_REPEATS` hand-placed
starts per floor, Table I's protocol, and the two are set side by side: the full model's
credited distances (per 10 s, at most the level-body bound), whether it breaks, whether its
repeats disagree widely (a chaotic gait, `sim.robot.field_summary.chaotic`), whether the
two models agree (`AGREEMENT`), and what a builder should doubt in the winner: its shape
(`sim.robot.leg.Leg.shape`: size, stroke, crank share) and how much of the full model's
distance stepping cannot explain (beyond the bound, feet sliding:
`sim.robot.walk_rows.SLIDING_SHARE`).
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass, field

from linkevo.sim.robot.field_summary import chaotic
from linkevo.sim.robot.hexapod import FLOORS, WALK_SECONDS, Robot
from linkevo.sim.robot.leg import Leg
from linkevo.sim.robot.walk_rows import (
    FLOOR_ORDER,
    LEGO_BUILD,
    SLIDING_SHARE,
    beyond_bound_share,
    credited_cm,
    slide_share,
    walked_row,
)
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
        beyond_bound_share: how far the full model's repeats go beyond their level-body
            bound (`sim.robot.walk_rows.beyond_bound_share`, their mean; NaN unknown).
        slide_share: how fast their feet slip while down over the body's speed
            (`sim.robot.walk_rows.slide_share`, their mean; NaN unknown).
    """

    floor: str
    lean_cm: float | None
    full_cm: tuple[float, ...]
    full_breaks: bool
    chaotic: bool
    beyond_bound_share: float = math.nan
    slide_share: float = math.nan

    @property
    def slides(self) -> bool:
        """Whether most of the full model's distance comes from sliding."""
        return self.slide_share > SLIDING_SHARE

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
    """A walk confirmed on the full model, floor by floor (`FLOOR_ORDER`), with the leg's
    shape (`sim.robot.leg.Leg.shape`)."""

    floors: tuple[FloorCheck, ...]
    shape: dict = field(default_factory=dict)

    @property
    def agrees(self) -> bool:
        """The models agree on every floor."""
        return all(f.agrees for f in self.floors)

    @property
    def chaotic(self) -> bool:
        """The full model's repeats disagree widely on some floor."""
        return any(f.chaotic for f in self.floors)

    @property
    def slides(self) -> bool:
        """Most of the full model's distance comes from sliding on some floor."""
        return any(f.slides for f in self.floors)

    def as_dict(self) -> dict:
        """The confirmation as JSON-able values (`best_confirmed.json`)."""
        return {
            "agrees": self.agrees,
            "chaotic": self.chaotic,
            "slides": self.slides,
            "shape": self.shape,
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
                    "beyond_bound_share": rounded(f.beyond_bound_share),
                    "slide_share": rounded(f.slide_share),
                    "slides": f.slides,
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
        rows = [walked_row({"cell": -1, "seconds": seconds}, floor, w, LEGO_BUILD) for w in walks]
        sound = [r for r in rows if not r["breaks"]]
        checks.append(
            FloorCheck(
                floor=floor,
                lean_cm=lean_cm.get(floor),
                full_cm=tuple(credited_cm(r) if not r["breaks"] else math.nan for r in rows),
                full_breaks=2 * sum(w.breaks for w in walks) > len(walks),
                chaotic=chaotic(walks),
                beyond_bound_share=_mean([beyond_bound_share(r) for r in sound]),
                slide_share=_mean([slide_share(r) for r in sound]),
            )
        )
    return Confirmation(tuple(checks), leg.shape())


def _mean(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return statistics.fmean(finite) if finite else math.nan


def rounded(value: float, digits: int = 3) -> float | None:
    return None if not math.isfinite(value) else round(value, digits)
