"""Frail legs (`sim.robot.frailty`) against beam theory on hand-made legs, each correction
apart (the tripod's lone foot, the sag by the beam's angle, an extended crank held at the
axle, the foot's layers, the splay's drop), the three-valued verdict over the parameters'
ranges, and the break rule on the real engine."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from linkevo.sim.linkage.linkage_doc import from_document
from linkevo.sim.robot.frailty import (
    BEST,
    FRAIL,
    NOMINAL,
    SOUND,
    UNCERTAIN,
    WORST,
    cantilever_end_moment_mm,
    cantilever_tip_load_mm,
    foot_load_n,
    frailty,
)
from linkevo.sim.robot.hexapod import BEAM_KG_PER_MODULE, FLOORS, Frame
from linkevo.sim.robot.leg import Leg, leg_from_genome
from linkevo.sim.robot.walking import WalkSettings, walk

ROOT = Path(__file__).parents[2]
ANGLES = np.linspace(0, 2 * np.pi, 360, endpoint=False)


def hand_leg(drop: float, run: float, layers: tuple[int, ...], on_crank: bool = False) -> Leg:
    """A hand-made leg (modules): a crank of one module on layer `layers[0]` turning about
    node 0, and a beam on layer `layers[1]` pinned to the crank's tip (node 1) reaching the
    foot (node 2) `run` across and `drop` down; with `on_crank` that beam is the crank's own
    extension (the crank's part). More layers put more beams at the foot (node 2), each a
    spoke from a frame node (node 3) of its own part."""
    crank = np.stack([np.cos(ANGLES), np.sin(ANGLES)], axis=1)
    foot = crank + np.array([run, -drop])
    frame_node = np.tile([run, -drop - 3.0], (len(ANGLES), 1))
    paths = np.stack([np.zeros_like(crank), crank, foot, frame_node])
    beams = [(0, 1), (1, 2), *[(3, 2)] * (len(layers) - 2)]
    parts = [0, 0 if on_crank else 1, *range(2, len(layers))]
    return Leg(
        paths=paths,
        beams=np.array(beams, dtype=np.int64),
        part=np.array(parts, dtype=np.int64),
        layer=np.array(layers, dtype=np.int64),
        frame_nodes=np.array([0, 3], dtype=np.int64),
        foot=2,
        built=True,
    )


def test_beam_theorys_cantilevers():
    # a 15-module beam (120 mm) with 10 N at its tip: 10 * 120^3 / (3 E I)
    assert cantilever_tip_load_mm(10.0, 120.0, 2300.0, 200.0) == pytest.approx(
        17_280_000 / (3 * 2300 * 200.0), rel=1e-12
    )
    # the same beam under a 100 N·mm end moment: M L^2 / (2 E I)
    assert cantilever_end_moment_mm(100.0, 120.0, 2300.0, 124.0) == pytest.approx(
        1_440_000 / (2 * 2300 * 124.0), rel=1e-12
    )


def test_the_lone_foot_of_a_tripod_carries_half_the_robot():
    leg = hand_leg(drop=10.0, run=0.0, layers=(0, 0))
    frame = Frame()
    beams_kg = 6 * BEAM_KG_PER_MODULE * (1.0 + 10.0)
    assert foot_load_n(frame, leg) == pytest.approx((frame.mass_kg + beams_kg) * 9.81 / 2)


def test_the_sag_goes_with_the_square_of_the_cosine_of_the_beams_angle():
    w = foot_load_n(Frame(), hand_leg(drop=6.0, run=8.0, layers=(0, 0)))
    slanted = frailty(hand_leg(drop=6.0, run=8.0, layers=(0, 0)), 0.0)
    # the beam from the crank tip to the foot is 10 modules (80 mm) at cos = 0.8
    expected = cantilever_tip_load_mm(w, 80.0, NOMINAL.e_n_mm2, NOMINAL.i_in_mm4) * 0.8**2
    assert slanted.nominal.sag_mm == pytest.approx(expected, rel=1e-9)
    vertical = frailty(hand_leg(drop=10.0, run=0.0, layers=(0, 0)), 0.0)
    assert vertical.nominal.sag_mm == pytest.approx(0.0, abs=1e-9)  # along the beam: no sag


def test_a_foot_on_the_cranks_own_part_hangs_from_the_axle():
    on_crank = frailty(hand_leg(drop=6.0, run=8.0, layers=(0, 0), on_crank=True), 0.0)
    pinned = frailty(hand_leg(drop=6.0, run=8.0, layers=(0, 0)), 0.0)
    assert on_crank.nominal.sag_mm > pinned.nominal.sag_mm
    g = on_crank.geometry  # the cantilever runs from the axle (node 0) to the foot
    path = hand_leg(drop=6.0, run=8.0, layers=(0, 0)).paths[2]
    stance = path[:, 1] <= (path[:, 1].min() + path[:, 1].max()) / 2
    np.testing.assert_allclose(g.hang_mm, np.linalg.norm(path[stance], axis=1) * 8.0)


def test_the_splay_is_the_foots_layers_offset_levering_the_reach_and_drops_the_foot():
    leg = hand_leg(drop=10.0, run=0.0, layers=(0, 2, 4))  # the foot joins layers 2 and 4
    found = frailty(leg, 0.0)
    g = found.geometry
    assert g.offset_mm == pytest.approx(3 * 8.0)  # the foot's layers' mean, 3, from 0
    w, s = g.load_n, NOMINAL
    splay = cantilever_end_moment_mm(w * 24.0, 1.0, s.e_n_mm2, s.i_out_mm4) * g.reach_mm**2
    splay += g.crossings * math.radians(s.pin_play_deg) * g.reach_mm
    drop = splay**2 / (2 * g.reach_mm)
    worst = int(np.argmax(drop))
    assert found.nominal.splay_mm == pytest.approx(splay[worst], rel=1e-9)
    assert found.nominal.give_mm == pytest.approx(drop[worst], rel=1e-9)  # no sag: vertical


def test_the_pin_moment_is_the_force_levered_across_the_widest_bridge():
    leg = hand_leg(drop=10.0, run=0.0, layers=(0, 2))
    found = frailty(leg, 20.0)
    assert found.best.pin_moment_nmm == pytest.approx(20.0 * 16.0 * BEST.pin_lever)
    assert found.worst.pin_moment_nmm == pytest.approx(20.0 * 16.0 * WORST.pin_lever)


def test_the_verdict_is_three_valued_over_the_ranges():
    short = frailty(hand_leg(drop=4.0, run=0.0, layers=(0, 1)), 5.0)
    assert short.verdict == SOUND and not short.frail and short.reason() == ""
    # a pin bridging two layers at 25 N: 200-400 N·mm against a yield of 350-430
    straddling = frailty(hand_leg(drop=4.0, run=0.0, layers=(0, 2)), 25.0)
    assert straddling.verdict == UNCERTAIN and not straddling.frail
    assert straddling.as_dict()["limits_passed"]  # the worst end passes a limit
    bent = frailty(hand_leg(drop=4.0, run=0.0, layers=(0, 2)), 60.0)  # 480-960 N·mm
    assert bent.verdict == FRAIL and bent.reason().startswith("frail: a pin is bent")
    long = frailty(hand_leg(drop=12.0, run=24.0, layers=(0, 0)), 0.0)  # a long slanted foot
    assert long.verdict == FRAIL and "more than half its" in long.reason()


def test_the_walk_reports_the_verdict_and_breaks_only_a_frail_leg():
    sound = json.loads((ROOT / "tests" / "data" / "sound_leg.json").read_text())
    leg = leg_from_genome(*from_document(sound))
    walked = walk(leg, FLOORS["flat"], settings=WalkSettings(seconds=1.0))
    assert walked.frailty is not None and not walked.frailty.frail and not walked.breaks
    furthest_out = max(walked.spacers.values())  # the frailest slot: the most spacers
    expected = frailty(leg, walked.pin_force_n[2], spacer=furthest_out)
    assert walked.frailty.as_dict() == expected.as_dict()
    frail_leg = hand_leg(drop=12.0, run=24.0, layers=(0, 0))
    walked = walk(frail_leg, FLOORS["flat"], settings=WalkSettings(seconds=1.0))
    assert walked.frailty is not None and walked.frailty.verdict == FRAIL
    assert walked.breaks and "frail: the foot gives" in walked.reason
