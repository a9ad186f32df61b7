"""Provides `judge_prototyping`: the paper's prototyping claims (Table I, Sections V-B and
VI) judged on a predicted Table I (`walk_study.predict_table_one`), on each robot model.

A robot **walks** on a floor when it does not break and its mean forward distance in the
walk is above `WALK_CM`. Each claim is a count over the drawn trials (one robot, or one
pair of robots, per draw), judged by the report's rule in its sign-test form: reproduced
when more than half of the draws go the claimed way and the two-sided exact binomial
(sign) test against one half gives p < 0.05; direction only when more than half go the
claimed way without that; contradicted when fewer than half do with p < 0.05; otherwise
not reproduced. A claim over several parts takes its weakest part's verdict. With one
draw (the paper's protocol to the letter) no claim can be more than "direction only".
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd
from scipy.stats import binomtest

from linkevo.orchestrator.report.stats import ALPHA
from linkevo.orchestrator.report.verdicts import (
    CONTRADICTED,
    DIRECTION_ONLY,
    NOT_REPRODUCED,
    NOT_TESTABLE,
    REPRODUCED,
    weakest,
)
from linkevo.sim.robot.hexapod import FLOORS, ROBOT_MODELS

WALK_CM = 10.0
"""A robot walks when it moves forward more than this in the walk without breaking: a
quarter of the paper's slowest walker (39.4 cm in 10 s); less is walking on the spot."""


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


def _distance(table: pd.DataFrame) -> pd.Series:
    """Mean forward distance per row, -inf where the robot has none (it does not turn)."""
    return pd.to_numeric(table.mean_distance_cm, errors="coerce").fillna(-np.inf)


def walks(table: pd.DataFrame) -> pd.Series:
    """Whether each row's robot walks on its floor (`WALK_CM`, no break)."""
    return ~table.breaks.astype(bool) & (_distance(table) > WALK_CM)


def _per_draw(table: pd.DataFrame, approach: str, robot: str) -> pd.DataFrame:
    """One row per draw of a robot: its distance and whether it walks, per floor."""
    rows = table[(table.approach == approach) & (table.robot == robot)]
    return rows.assign(d=_distance(rows), w=walks(rows)).pivot(
        index="draw", columns="floor", values=["d", "w"]
    )


def _count(part: str, yes: int, n: int) -> tuple[str, str]:
    return sign_verdict(yes, n), f"{part}: {yes} of {n} draws"


def _claims() -> list[tuple[str, str, Callable[[pd.DataFrame], list[tuple[str, str]]]]]:
    """The claims: (claim, where, its parts on one model's table)."""

    def cannot_walk(approach: str, robot: str):
        def parts(t):
            d = _per_draw(t, approach, robot)
            if d.empty:
                return []
            never = ~d["w"].any(axis=1)
            return [_count(f"{approach} {robot} walks on neither floor", int(never.sum()), len(d))]

        return parts

    def walked(t):
        out = []
        for approach, robot in (
            ("MAP-WH", "first"),
            ("MAP-LIS", "modified"),
            ("MAP-ST", "first"),
            ("MAP-ST", "modified"),
            ("MAP-AU", "first"),
            ("MAP-AU", "modified"),
        ):
            d = _per_draw(t, approach, robot)
            if not d.empty:
                both = d["w"].all(axis=1)
                out.append(
                    _count(f"{approach} {robot} walks on both floors", int(both.sum()), len(d))
                )
        return out

    def against_first(approach: str, floors: tuple[str, ...], quicker: bool):
        def parts(t):
            first, modified = _per_draw(t, approach, "first"), _per_draw(t, approach, "modified")
            if first.empty or modified.empty:
                return []
            both = first.index.intersection(modified.index)
            out = []
            for floor in floors:
                a, b = first.loc[both, ("d", floor)], modified.loc[both, ("d", floor)]
                differ = a != b  # a tie goes neither way
                claimed = (b > a) if quicker else (b < a)
                word = "quicker" if quicker else "slower"
                part = f"{approach} modified {word} than first on {floor}"
                out.append(_count(part, int(claimed[differ].sum()), int(differ.sum())))
            return out

        return parts

    def carpet_only(t):
        out = []
        for approach, robot in t[["approach", "robot"]].drop_duplicates().itertuples(index=False):
            d = _per_draw(t, approach, robot)
            faster = d[("d", "carpet")] > d[("d", "flat")]
            if approach == "MAP-LIS" and robot == "modified":
                out.append(
                    _count("MAP-LIS modified faster on carpet than flat", int(faster.sum()), len(d))
                )
            else:
                out.append(
                    _count(f"{approach} {robot} not faster on carpet", int((~faster).sum()), len(d))
                )
        return out

    return [
        (
            "The MAP-LIS first robot was incapable of walking: its legs were too large to "
            "support the weight of the robot frame",
            "Section V-B",
            cannot_walk("MAP-LIS", "first"),
        ),
        (
            "The MAP-WH modified robot (a larger path with much higher lift) was not capable "
            "of producing a walking gait",
            "Section V-B",
            cannot_walk("MAP-WH", "modified"),
        ),
        ("The other six robots walked on both floors", "Table I", walked),
        (
            "The MAP-ST modified robot (a slightly wider path) walked quicker on the flat floor",
            "Section V-B",
            against_first("MAP-ST", ("flat",), quicker=True),
        ),
        (
            "The modified MAP-AU robot moved slightly slower than the original on both floors",
            "Section V-B",
            against_first("MAP-AU", FLOORS, quicker=False),
        ),
        (
            "The MAP-LIS modified robot was the only one that walked faster on the carpet "
            "than the flat floor",
            "Section V-B",
            carpet_only,
        ),
    ]


def judge_prototyping(table: pd.DataFrame) -> pd.DataFrame:
    """Returns one row per claim: claim, where, and per robot model (`ROBOT_MODELS`)
    `verdict_<model>` and `evidence_<model>`, plus `models_agree`.

    Args:
        table: `predict_table_one`'s rows (approach, draw, robot, floor, model,
            mean_distance_cm, breaks).
    """
    rows = []
    for claim, where, parts in _claims():
        row: dict[str, object] = {"claim": claim, "where": where}
        for model in ROBOT_MODELS:
            found = parts(table[table.model == model])
            judged = [v for v, _ in found if v != NOT_TESTABLE]
            row[f"verdict_{model}"] = weakest(judged) if judged else NOT_TESTABLE
            row[f"evidence_{model}"] = "; ".join(e for _, e in found) or "no such robot"
        row["models_agree"] = len({row[f"verdict_{m}"] for m in ROBOT_MODELS}) == 1
        rows.append(row)
    return pd.DataFrame(rows)
