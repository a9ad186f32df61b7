"""Tests `orchestrator.table_one_verdicts` on constructed Table I predictions: at its default
number of draws the sign test can say "reproduced", and `hexapod study --help` states that
power; a draw with no modification possible bears on no claim about the modified robot;
the paper's statements on speeds are judged as written."""

from __future__ import annotations

import pandas as pd
import pytest

from linkevo.orchestrator.cli import build_parser
from linkevo.orchestrator.table_one_verdicts import (
    DEFAULT_DRAWS,
    NO_MODIFICATION,
    SAME_SPEED,
    judge_prototyping,
    sign_power,
    smallest_draws,
)
from linkevo.sim.study import MAP_ELITES

# Each robot's (flat, carpet) distance in cm, as the paper's Table I has them where a robot
# walked, and 0 where it did not (MAP-WH modified, MAP-LIS first).
PAPER = {
    ("MAP-WH", "first"): (73.6, 63.6),
    ("MAP-WH", "modified"): (0.0, 0.0),
    ("MAP-LIS", "first"): (0.0, 0.0),
    ("MAP-LIS", "modified"): (40.4, 48.0),
    ("MAP-ST", "first"): (39.4, 39.2),  # the text: no speed lost, not faster on carpet
    ("MAP-ST", "modified"): (77.6, 39.0),
    ("MAP-AU", "first"): (61.8, 59.4),
    ("MAP-AU", "modified"): (51.0, 50.0),
}


def table(draws: int, distances=PAPER, unmodified: tuple[str, ...] = ()) -> pd.DataFrame:
    """A predicted Table I with `draws` identical draws per approach, on both models; the
    approaches in `unmodified` have no modified robot in any draw."""
    rows = []
    for (approach, robot), cms in distances.items():
        for draw in range(draws):
            for floor, cm in zip(("flat", "carpet"), cms, strict=True):
                for model in ("lean", "full"):
                    none = robot == "modified" and approach in unmodified
                    rows.append(
                        {
                            "approach": approach,
                            "draw": draw,
                            "robot": robot,
                            "floor": floor,
                            "model": model,
                            "mean_distance_cm": None if none else cm,
                            "breaks": None if none else cm == 0.0,
                            "rule": f"{NO_MODIFICATION}: no buildable neighbour" if none else "",
                        }
                    )
    return pd.DataFrame(rows)


def test_every_draw_agreeing_is_reproduced_at_the_default_draws_and_not_at_five():
    verdicts = judge_prototyping(table(DEFAULT_DRAWS))
    assert len(verdicts) == 13  # every statement of the prototyping paragraphs
    assert (verdicts.verdict_lean == "reproduced").all(), verdicts[["claim", "verdict_lean"]]
    assert (verdicts.verdict_full == "reproduced").all()
    assert verdicts.models_agree.all()
    assert set(judge_prototyping(table(5)).verdict_lean) == {"direction only"}  # p 0.0625


def test_the_default_draws_and_their_power_are_what_the_help_says():
    assert smallest_draws() == 6
    assert sign_power(5, 1.0) == 0.0 and sign_power(6, 1.0) == pytest.approx(1.0)
    assert 0.0 < sign_power(DEFAULT_DRAWS, 0.8) < sign_power(DEFAULT_DRAWS, 0.9) < 1.0
    parser = build_parser()
    study = parser._subparsers._group_actions[0].choices["hexapod"]
    study = study._subparsers._group_actions[0].choices["study"]
    drawn = next(a for a in study._actions if a.dest == "trials_drawn")
    assert drawn.default == DEFAULT_DRAWS
    words = " ".join(drawn.help.split())
    assert f"default {DEFAULT_DRAWS};" in words
    assert f"from {smallest_draws()} draws on" in words
    assert f"a chance of {sign_power(DEFAULT_DRAWS, 0.9):.2f} when 9 in 10" in words
    assert f"({sign_power(DEFAULT_DRAWS, 0.8):.2f} at 8 in 10" in words


def test_a_draw_with_no_modification_possible_is_counted_apart():
    verdicts = judge_prototyping(table(DEFAULT_DRAWS, unmodified=("MAP-ST",))).set_index("claim")
    quicker = verdicts.loc[
        "The MAP-ST modified robot (a slightly wider path) walked quicker on the flat floor"
    ]
    assert quicker.verdict_lean == "not testable"
    assert "0 of 0 draws (10 more: no modification possible)" in quicker.evidence_lean
    first = verdicts.loc["The MAP-ST first robot did not lose any speed on the carpet"]
    assert first.verdict_lean == "reproduced" and "more:" not in first.evidence_lean


@pytest.mark.parametrize(
    ("first_flat", "first_carpet", "same"),
    [(61.8, 59.4, "reproduced"), (61.8, 61.8 * (1 - SAME_SPEED) - 0.1, "contradicted")],
)
def test_similar_speeds_are_within_the_same_speed_band(first_flat, first_carpet, same):
    distances = {**PAPER, ("MAP-AU", "first"): (first_flat, first_carpet)}
    verdicts = judge_prototyping(table(DEFAULT_DRAWS, distances)).set_index("claim")
    similar = verdicts.loc["The MAP-AU first robot moved similarly on both floors"]
    assert similar.verdict_lean == same


def test_every_approach_of_the_table_is_one_the_study_builds_from():
    assert {a for a, _ in PAPER} == set(MAP_ELITES)
