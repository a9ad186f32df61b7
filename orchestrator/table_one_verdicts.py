"""Provides `judge_prototyping`: the paper's prototyping claims (Table I, Sections V-B and
VI) judged on a predicted Table I (`walk_study.predict_table_one`), on each robot model.

A robot **walks** on a floor when it does not break and its mean forward distance in the
walk is above `WALK_CM`. Each claim is a count over the drawn trials (one robot, or one
pair of robots, per draw), judged by the report's rule in its sign-test form: reproduced
when more than half of the draws go the claimed way and the two-sided exact binomial
(sign) test against one half gives p < 0.05; direction only when more than half go the
claimed way without that; contradicted when fewer than half do with p < 0.05; otherwise
not reproduced. A claim over several parts takes its weakest part's verdict. With one
draw (the paper's protocol to the letter) no claim can be more than "direction only": the
sign test reaches p < 0.05 first at `smallest_draws()` draws (6, every one going the
claimed way), and `DEFAULT_DRAWS` gives it the power `sign_power` states.

A draw whose map has no buildable neighbouring region with the change the paper's
builders sought has no modified robot ("no modification possible",
`NO_MODIFICATION`): it bears on no claim about the modified robot, and the
evidence counts it apart. Speeds are "the same" within `SAME_SPEED` of each other.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.stats import binom, binomtest

from linkevo.orchestrator.report.stats import ALPHA
from linkevo.orchestrator.report.verdicts import (
    CONTRADICTED,
    DIRECTION_ONLY,
    NOT_REPRODUCED,
    NOT_TESTABLE,
    REPRODUCED,
    weakest,
)
from linkevo.sim.robot.hexapod import CARPET, FLAT, ROBOT_MODELS
from linkevo.sim.robot.walk_rows import FLOOR_ORDER
from linkevo.sim.study import MAP_ELITES, ROBOTS

NO_MODIFICATION = "no modification possible"
"""The rule of a draw with no modified robot (no buildable neighbour has the sought change)."""

WALK_CM = 10.0
"""A robot walks when it moves forward more than this in the walk without breaking: a
quarter of the paper's slowest walker (39.4 cm in 10 s); less is walking on the spot."""
SAME_SPEED = 0.1
"""Two walking speeds are "the same" (or "similar") when the slower is within this share of
the faster: the paper's own pairs so called differ by 0.5-3.9 % (MAP-ST modified on
carpet 39.0 against the first's 39.6 cm; MAP-AU first 61.8 on flat, 59.4 on carpet), those
it calls "slightly slower" by 13.6-17.5 %."""
DEFAULT_DRAWS = 10
"""Trials drawn per approach by default: every trial of a 10-trial study grid. A claim is
then reproduced with 9 or 10 of 10 draws going its way (`sign_power`)."""


def sign_verdict(yes: int, n: int) -> str:
    """Returns the verdict on "the claimed outcome holds" from `yes` of `n` draws going the
    claimed way (module docstring)."""
    if n == 0:
        return NOT_TESTABLE
    p = binomtest(yes, n, 0.5).pvalue
    if 2 * yes > n:
        return REPRODUCED if p < ALPHA else DIRECTION_ONLY
    if 2 * yes < n and p < ALPHA:
        return CONTRADICTED
    return NOT_REPRODUCED


def smallest_draws() -> int:
    """Returns the fewest draws at which the sign test can say "reproduced": every draw
    going the claimed way gives p < `ALPHA`."""
    n = 1
    while binomtest(n, n, 0.5).pvalue >= ALPHA:
        n += 1
    return n


def sign_power(n: int, share: float) -> float:
    """Returns the chance that a claim is judged reproduced over `n` draws when each draw
    goes the claimed way with probability `share`, independently."""
    return float(
        sum(binom.pmf(yes, n, share) for yes in range(n + 1) if sign_verdict(yes, n) == REPRODUCED)
    )


def _distance(table: pd.DataFrame) -> pd.Series:
    """Mean forward distance per row, -inf where the robot has none (it does not turn)."""
    return pd.to_numeric(table.mean_distance_cm, errors="coerce").fillna(-np.inf)


def walks(table: pd.DataFrame) -> pd.Series:
    """Whether each row's robot walks on its floor (`WALK_CM`, no break)."""
    return ~table.breaks.astype(bool) & (_distance(table) > WALK_CM)


@dataclass(frozen=True)
class Draw:
    """One drawn trial of an approach on one model: each robot's distance (cm) and whether
    it walks, per floor (a robot or floor the table lacks is missing)."""

    cm: dict[tuple[str, str], float]
    walks: dict[tuple[str, str], bool]
    unmodified: bool = False

    def has(self, robot: str) -> bool:
        return all((robot, f) in self.cm for f in FLOOR_ORDER)


def draws(table: pd.DataFrame, approach: str) -> list[Draw]:
    """Returns one model's draws of an approach, in draw order (a "no modification
    possible" row marks its draw and is no robot)."""
    rows = table[table.approach == approach].assign(d=_distance, w=walks)
    out = []
    for _, part in rows.groupby("draw", sort=True):
        none = part.rule.astype(str).str.startswith(NO_MODIFICATION)
        robots = part[~none]
        keys = list(zip(robots.robot, robots.floor, strict=True))
        cm, walked = dict(zip(keys, robots.d, strict=True)), dict(zip(keys, robots.w, strict=True))
        out.append(Draw(cm, walked, unmodified=bool(none.any())))
    return out


Test = Callable[..., "bool | None"]
"""Whether a draw goes the claimed way (given the draw, and the paired draw of the part's
`versus` approach where it has one); None where it does not bear on it (a tie, or a robot
the draw lacks)."""


@dataclass(frozen=True)
class Part:
    """One count a claim rests on: of an approach's draws that bear on `test`, how many go
    the claimed way. A part that compares two approaches (`versus`) pairs their draws in
    draw order: the draws are independent, so any pairing is a fair sample."""

    approach: str
    text: str
    test: Test
    versus: str = ""

    def judge(self, found: list[Draw], others: list[Draw] | None = None) -> tuple[str, str]:
        """Returns the verdict and its evidence over the draws (and `versus`'s)."""
        pairs = (
            [(d,) for d in found]
            if not self.versus
            else list(zip(found, others or [], strict=False))
        )
        said = [s for s in (self.test(*p) for p in pairs) if s is not None]
        yes = sum(said)
        evidence = f"{self.approach} {self.text}: {yes} of {len(said)} draws"
        unmodified = sum(d.unmodified for d in found)
        if unmodified and "modified" in self.text:
            evidence += f" ({unmodified} more: no modification possible)"
        return sign_verdict(yes, len(said)), evidence


def never_walks(robot: str) -> Test:
    return lambda d: not any(d.walks[(robot, f)] for f in FLOOR_ORDER) if d.has(robot) else None


def walks_on_both(robot: str) -> Test:
    return lambda d: all(d.walks[(robot, f)] for f in FLOOR_ORDER) if d.has(robot) else None


def modified_than_first(floor: str, quicker: bool) -> Test:
    def test(d: Draw) -> bool | None:
        if not (d.has("first") and d.has("modified")):
            return None
        first, modified = d.cm[("first", floor)], d.cm[("modified", floor)]
        if first == modified:
            return None  # a tie goes neither way
        return modified > first if quicker else modified < first

    return test


def same_speed(a: float, b: float) -> bool:
    """Whether two walking speeds (cm) are the same within `SAME_SPEED`."""
    return min(a, b) >= (1 - SAME_SPEED) * max(a, b)


def as_fast(robot: str, floor: str, other: tuple[str, str], how: str) -> Test:
    """A robot on a floor against another (robot, floor) of the same draw: "same" (both
    walk, at the same speed), "not slower" (it walks, no slower beyond the same-speed
    band) or "slower" (its distance is the shorter)."""

    def test(d: Draw) -> bool | None:
        if not (d.has(robot) and d.has(other[0])):
            return None
        mine, theirs = d.cm[(robot, floor)], d.cm[other]
        both = d.walks[(robot, floor)] and d.walks[other]
        if how == "same":
            return both and same_speed(mine, theirs)
        if how == "not slower":
            return both and mine >= (1 - SAME_SPEED) * theirs
        return None if mine == theirs else mine < theirs

    return test


def further_than(robot: str, floor: str, cm: float) -> Test:
    return lambda d: d.walks[(robot, floor)] and d.cm[(robot, floor)] > cm if d.has(robot) else None


def slower_than_other(robot: str, other: str, floor: str) -> Test:
    """A robot against the paired draw's `other` robot of the part's `versus` approach."""

    def test(d: Draw, o: Draw) -> bool | None:
        if not (d.has(robot) and o.has(other)):
            return None
        mine, theirs = d.cm[(robot, floor)], o.cm[(other, floor)]
        return None if mine == theirs else mine < theirs

    return test


def faster_on_carpet(robot: str, faster: bool) -> Test:
    def test(d: Draw) -> bool | None:
        if not d.has(robot):
            return None
        return (d.cm[(robot, CARPET)] > d.cm[(robot, FLAT)]) == faster

    return test


@dataclass(frozen=True)
class Claim:
    """One of the paper's prototyping claims: its words, where it is made, and its parts."""

    text: str
    where: str
    parts: tuple[Part, ...]


def _carpet_parts() -> tuple[Part, ...]:
    """ "The MAP-LIS modified robot was the only one faster on carpet": that one is, and
    every other robot is not."""
    out = []
    for approach in MAP_ELITES:
        for robot in ROBOTS:
            only = (approach, robot) == ("MAP-LIS", "modified")
            text = (
                f"{robot} faster on carpet than flat" if only else f"{robot} not faster on carpet"
            )
            out.append(Part(approach, text, faster_on_carpet(robot, only)))
    return tuple(out)


CLAIMS: tuple[Claim, ...] = (
    Claim(
        "The MAP-WH first robot walked over 70 cm on the flat floor",
        "Section V-B",
        (Part("MAP-WH", "first walks over 70 cm on flat", further_than("first", FLAT, 70.0)),),
    ),
    Claim(
        "The MAP-WH first robot was slightly slower on the carpeted floor",
        "Section V-B",
        (
            Part(
                "MAP-WH",
                "first slower on carpet",
                as_fast("first", CARPET, ("first", FLAT), "slower"),
            ),
        ),
    ),
    Claim(
        "The MAP-LIS first robot was incapable of walking: its legs were too large to "
        "support the weight of the robot frame",
        "Section V-B",
        (Part("MAP-LIS", "first walks on neither floor", never_walks("first")),),
    ),
    Claim(
        "The MAP-WH modified robot (a larger path with much higher lift) was not capable "
        "of producing a walking gait",
        "Section V-B",
        (Part("MAP-WH", "modified walks on neither floor", never_walks("modified")),),
    ),
    Claim(
        "The other six robots walked on both floors",
        "Table I",
        tuple(
            Part(approach, f"{robot} walks on both floors", walks_on_both(robot))
            for approach, robot in (
                ("MAP-WH", "first"),
                ("MAP-LIS", "modified"),
                ("MAP-ST", "first"),
                ("MAP-ST", "modified"),
                ("MAP-AU", "first"),
                ("MAP-AU", "modified"),
            )
        ),
    ),
    Claim(
        "The MAP-LIS modified robot was not very quick (slower on flat than the MAP-AU "
        "first robot, which moved quite fast)",
        "Section V-B",
        (
            Part(
                "MAP-LIS",
                "modified slower on flat than MAP-AU first",
                slower_than_other("modified", "first", FLAT),
                versus="MAP-AU",
            ),
        ),
    ),
    Claim(
        "The MAP-ST first robot walked quite slowly (slower on flat than the MAP-AU first "
        "robot, which moved quite fast)",
        "Section V-B",
        (
            Part(
                "MAP-ST",
                "first slower on flat than MAP-AU first",
                slower_than_other("first", "first", FLAT),
                versus="MAP-AU",
            ),
        ),
    ),
    Claim(
        "The MAP-ST first robot did not lose any speed on the carpet",
        "Section V-B",
        (
            Part(
                "MAP-ST",
                "first no slower on carpet than flat",
                as_fast("first", CARPET, ("first", FLAT), "not slower"),
            ),
        ),
    ),
    Claim(
        "The MAP-ST modified robot (a slightly wider path) walked quicker on the flat floor",
        "Section V-B",
        (
            Part(
                "MAP-ST", f"modified quicker than first on {FLAT}", modified_than_first(FLAT, True)
            ),
        ),
    ),
    Claim(
        "The MAP-ST modified robot maintained the same speed as the original on the carpet",
        "Section V-B",
        (
            Part(
                "MAP-ST",
                "modified as fast as first on carpet",
                as_fast("modified", CARPET, ("first", CARPET), "same"),
            ),
        ),
    ),
    Claim(
        "The MAP-AU first robot moved similarly on both floors",
        "Section V-B",
        (
            Part(
                "MAP-AU",
                "first as fast on carpet as on flat",
                as_fast("first", CARPET, ("first", FLAT), "same"),
            ),
        ),
    ),
    Claim(
        "The modified MAP-AU robot moved slightly slower than the original on both floors",
        "Section V-B",
        tuple(
            Part("MAP-AU", f"modified slower than first on {f}", modified_than_first(f, False))
            for f in FLOOR_ORDER
        ),
    ),
    Claim(
        "The MAP-LIS modified robot was the only one that walked faster on the carpet "
        "than the flat floor",
        "Section V-B (its Table I has the MAP-ST first robot faster on carpet too, 39.6 "
        "against 39.4 cm: the text is judged)",
        _carpet_parts(),
    ),
)
"""The paper's prototyping claims, in the paper's order."""


def judge_prototyping(table: pd.DataFrame) -> pd.DataFrame:
    """Returns one row per claim: claim, where, and per robot model (`ROBOT_MODELS`)
    `verdict_<model>` and `evidence_<model>`, plus `models_agree`.

    Args:
        table: `predict_table_one`'s rows (approach, draw, robot, floor, model,
            mean_distance_cm, breaks).
    """
    rows = []
    for claim in CLAIMS:
        row: dict[str, object] = {"claim": claim.text, "where": claim.where}
        for model in ROBOT_MODELS:
            mine = table[table.model == model]
            found = [
                part.judge(
                    draws(mine, part.approach), draws(mine, part.versus) if part.versus else None
                )
                for part in claim.parts
                if (mine.approach == part.approach).any()
                and (not part.versus or (mine.approach == part.versus).any())
            ]
            judged = [v for v, _ in found if v != NOT_TESTABLE]
            row[f"verdict_{model}"] = weakest(judged) if judged else NOT_TESTABLE
            row[f"evidence_{model}"] = "; ".join(e for _, e in found) or "no such robot"
        row["models_agree"] = len({row[f"verdict_{m}"] for m in ROBOT_MODELS}) == 1
        rows.append(row)
    return pd.DataFrame(rows)
