"""How legs are mounted side by side (`sim.robot.mounting`): neighbours that would meet are
put on spacers, legs built to meet strike each other in the walk, and a spacer's lever
loads the motor's axle."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from linkevo.sim.robot.frailty import frailty
from linkevo.sim.robot.hexapod import (
    FLOORS,
    LAYER_PITCH_M,
    LEG_SLOTS,
    MAX_SPACERS,
    TRIPOD_OFFSETS_DEG,
    Frame,
)
from linkevo.sim.robot.layers import segment_distance
from linkevo.sim.robot.leg import recipe_and_leg
from linkevo.sim.robot.mounting import (
    TOUCH_MODULES,
    Mounting,
    auto_spacers,
)
from linkevo.sim.robot.walking import WalkSettings, walk
from tests.helpers.walking import crank_leg, jansen_leg

TRIPODS = {s: math.radians(v) for s, v in TRIPOD_OFFSETS_DEG.items()}
SPACING = Frame().leg_spacing  # 16 cm: 20 modules between neighbouring axles
NONE = dict.fromkeys(LEG_SLOTS, 0)


def test_segment_distances_match_dense_sampling():
    rng = np.random.default_rng(3)
    a, b = rng.uniform(-5, 5, (2, 400, 2, 2))
    got = segment_distance(a[:, 0], a[:, 1], b[:, 0], b[:, 1])
    s = np.linspace(0, 1, 801)[:, None, None]
    pa = a[:, 0] + s * (a[:, 1] - a[:, 0])  # (801, 400, 2) points along each segment
    pb = b[:, 0] + s * (b[:, 1] - b[:, 0])
    dense = np.linalg.norm(pa[:, None] - pb[None, :], axis=-1).min(axis=(0, 1))
    assert np.allclose(got, dense, atol=0.02)
    assert (got[dense < 1e-3] == 0).all()  # crossing segments are at distance 0


def test_legs_narrower_than_the_spacing_need_no_spacers():
    assert auto_spacers(dict.fromkeys(LEG_SLOTS, crank_leg(8.0)), TRIPODS, SPACING) == NONE
    assert auto_spacers(dict.fromkeys(LEG_SLOTS, jansen_leg()), TRIPODS, SPACING) == NONE


def test_neighbours_that_would_meet_are_mounted_apart_and_then_never_touch():
    wide = crank_leg(12.0)  # 24 modules across, 20 between axles: the cranks cross
    legs = dict.fromkeys(LEG_SLOTS, wide)
    spacers = auto_spacers(legs, TRIPODS, SPACING)
    assert spacers == {**NONE, "left-middle": 1, "right-middle": 1}
    turn = np.linspace(0, 2 * math.pi, 720, endpoint=False)[:, None]
    phases = turn + np.array([TRIPODS[s] for s in LEG_SLOTS])  # (720, 6) the gait's turn
    assert Mounting(legs, spacers, Frame()).strikes(phases) == []
    struck = Mounting(legs, NONE, Frame()).strikes(phases)
    assert {(a, b) for a, b, _ in struck} == {
        ("left-front", "left-middle"),
        ("left-middle", "left-rear"),
        ("right-front", "right-middle"),
        ("right-middle", "right-rear"),
    }
    # The first strike is the first instant the two cranks (hand-placed in the side's
    # plane, sampled densely) come within a beam's width.
    a, b, first = struck[0]
    s = np.linspace(0, 1, 201)[:, None]

    def crank(slot: str) -> np.ndarray:
        """(T, 201, 2) points along the slot's crank at each instant."""
        axle = {"front": 20.0, "middle": 0.0, "rear": -20.0}[slot.split("-")[1]]
        phase = phases[:, LEG_SLOTS.index(slot)]
        tip = np.stack([-wide.facing() * 12 * np.cos(phase), 12 * np.sin(phase)], axis=1)
        return np.array([axle, 0.0]) + s[None] * tip[:, None]

    gap = np.linalg.norm(crank(a)[:, :, None] - crank(b)[:, None], axis=-1).min(axis=(1, 2))
    slack = 0.15  # the walk's angles fall on the leg's poses (a few tenths of a degree)
    assert gap[first] < TOUCH_MODULES + slack and (gap[:first] > TOUCH_MODULES - slack).all()


def test_a_leg_is_mounted_no_further_out_than_its_frame_axles_reach():
    import dataclasses

    legs = dict.fromkeys(LEG_SLOTS, dataclasses.replace(crank_leg(12.0), most_spacers=0))
    spacers = auto_spacers(legs, TRIPODS, SPACING)
    assert spacers == NONE  # the spacer it needs would take its axles past the longest
    phases = np.linspace(0, 2 * math.pi, 360, endpoint=False)[:, None] + np.array(
        [TRIPODS[s] for s in LEG_SLOTS]
    )
    assert Mounting(legs, spacers, Frame()).strikes(phases)


def test_a_built_legs_spacers_stop_at_the_longest_axle():
    from linkevo.sim.robot.parts import catalogue

    cells = json.loads((Path(__file__).parents[1] / "data" / "study_cells.json").read_text())
    for cell in cells[:10]:
        recipe, leg = recipe_and_leg(np.array(cell["genome"]), cell["mode"])
        longest = catalogue().axles[-1].size
        frame_axles = [j.fastener.size for j in recipe.parts.joints if j.frame]
        assert leg.most_spacers == min(MAX_SPACERS, longest - max(frame_axles))
        counts = recipe.parts.counts(leg.most_spacers)  # the axles at that many exist
        assert sum(counts.values()) > 0


@pytest.mark.parametrize("model", ["lean", "full"])
def test_legs_built_to_meet_break_the_walk_naming_them(model):
    wide = crank_leg(12.0)
    settings = WalkSettings(seconds=3.0, model=model)
    met = walk(wide, FLOORS["flat"], settings=settings, spacers=NONE)
    assert met.breaks and "the left-front and left-middle legs strike each other" in met.reason
    apart = walk(wide, FLOORS["flat"], settings=settings)
    assert apart.spacers == {**NONE, "left-middle": 1, "right-middle": 1}
    assert "strike" not in apart.reason


def test_each_spacer_layer_levers_the_foot_load_further_along_the_axle():
    leg = jansen_leg()
    near, far = frailty(leg, 0.0, spacer=0), frailty(leg, 0.0, spacer=6)
    pitch_mm = LAYER_PITCH_M * 1000
    assert far.geometry.axle_mm == pytest.approx(near.geometry.axle_mm + 6 * pitch_mm)
    rise = far.nominal.axle_moment_nmm - near.nominal.axle_moment_nmm
    assert rise == pytest.approx(near.geometry.load_n * 6 * pitch_mm)
    deep = frailty(leg, 0.0, spacer=40)  # a leg 32 cm out on its axle
    assert deep.frail and "the motor's axle is bent" in deep.reason()
