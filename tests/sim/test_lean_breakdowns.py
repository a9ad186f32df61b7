"""The lean model's breakdowns, collected (`tests/data/lean_breakdowns.json`): study legs whose
lean walk came apart (Table I's robots) and the walking trial's winner that the lean model
once credited with a walk it could not hold together. Each must end invalid with its reason,
or walk within 25 % of the full model's distance (docs/walking.md, "Where the lean model
breaks down")."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from linkevo.sim.robot.hexapod import FLOORS
from linkevo.sim.robot.leg import leg_from_genome
from linkevo.sim.robot.walking import WalkSettings, walk

BREAKDOWNS = json.loads((Path(__file__).parents[1] / "data" / "lean_breakdowns.json").read_text())
STUDY_CELLS = json.loads((Path(__file__).parents[1] / "data" / "study_cells.json").read_text())


@pytest.mark.parametrize("case", BREAKDOWNS, ids=[c["robot"] for c in BREAKDOWNS])
def test_a_lean_breakdown_is_invalid_with_its_reason_or_walks_as_the_full_model(case):
    leg = leg_from_genome(np.array(case["genome"]), case["mode"])
    lean = walk(leg, FLOORS["flat"], settings=WalkSettings(seconds=2.0))
    if lean.invalid:
        assert math.isnan(lean.distance_m) and lean.breaks
        fastest = f"{leg.fastest_joint_mm_per_deg():.0f} mm per crank degree"
        assert (
            lean.reason.startswith("invalid: the lean model came apart") and fastest in lean.reason
        )
        return
    full = walk(leg, FLOORS["flat"], settings=WalkSettings(seconds=2.0, model="full"))
    assert abs(lean.distance_m - full.distance_m) <= 0.25 * abs(full.distance_m)


def test_the_breakdowns_whip_a_joint_round_faster_than_most_study_legs():
    """What the collected breakdowns share: a joint near a toggle, moving tens to hundreds of
    mm per crank degree, where most buildable study legs' move a few."""
    study = [
        leg_from_genome(np.array(c["genome"]), c["mode"]).fastest_joint_mm_per_deg()
        for c in STUDY_CELLS
    ]
    broke = [
        leg_from_genome(np.array(c["genome"]), c["mode"]).fastest_joint_mm_per_deg()
        for c in BREAKDOWNS
    ]
    assert np.median(broke) > 3 * np.percentile(study, 90)
    assert min(broke) > np.median(study)
