"""Frail legs (`sim.robot.frailty`) against beam theory on hand-made legs, and the break rule on
the real engine: the study's benchmark leg (the MAP-LIS first robot, whose real
counterpart's legs were "too large to support the weight of the robot frame") is frail;
a short leg is not."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from linkevo.sim.linkage.linkage_doc import from_document
from linkevo.sim.robot.frailty import (
    ABS_E_N_MM2,
    FRAIL_FOOT_MM,
    I_IN_MM4,
    I_OUT_MM4,
    PIN_PLAY_RAD,
    cantilever_end_moment_mm,
    cantilever_tip_load_mm,
    foot_load_n,
    frailty,
)
from linkevo.sim.robot.hexapod import BEAM_KG_PER_MODULE, FLOORS, Frame
from linkevo.sim.robot.leg import Leg, leg_from_genome
from linkevo.sim.robot.walking import WalkSettings, walk

ROOT = Path(__file__).parents[2]


def test_a_technic_beams_sections_are_the_hand_computed_ones():
    # 7.2 mm square, a 4.8 mm hole: in plane t(h^3 - d^3)/12, out of plane (h - d) t^3/12
    assert pytest.approx(7.2 * (373.248 - 110.592) / 12, rel=1e-12) == I_IN_MM4  # 157.6
    assert pytest.approx(2.4 * 373.248 / 12, rel=1e-12) == I_OUT_MM4  # 74.65
    # a 15-module beam (120 mm) with 10 N at its tip, in plane: 10 * 120^3 / (3 E I)
    assert cantilever_tip_load_mm(10.0, 120.0, I_IN_MM4) == pytest.approx(
        17_280_000 / (3 * 2300 * 157.5936), rel=1e-9
    )  # 15.9 mm
    # the same beam under a 100 N·mm end moment, out of plane: M L^2 / (2 E I)
    assert cantilever_end_moment_mm(100.0, 120.0, I_OUT_MM4) == pytest.approx(
        1_440_000 / (2 * 2300 * 74.6496), rel=1e-9
    )


def hand_leg(reach: float, extension: float, layers: tuple[int, int]) -> Leg:
    """A hand-made leg (modules): a crank of one module on layer `layers[0]` turning about
    node 0, and a beam on layer `layers[1]` pinned to the crank's tip (node 1) running
    `extension` modules straight down to the foot (node 2), `reach` from the axle at most."""
    angles = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    crank = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    foot = crank + np.array([0.0, -extension])
    paths = np.stack([np.zeros_like(crank), crank, foot])
    assert np.linalg.norm(foot, axis=1).max() == pytest.approx(reach)
    return Leg(
        paths=paths,
        beams=np.array([(0, 1), (1, 2)], dtype=np.int64),
        part=np.array([0, 1], dtype=np.int64),
        layer=np.array(layers, dtype=np.int64),
        frame_nodes=np.array([0], dtype=np.int64),
        foot=2,
        built=True,
    )


def test_the_foot_deflection_is_beam_theory_on_the_legs_own_build():
    leg = hand_leg(reach=11.0, extension=10.0, layers=(0, 2))
    found = frailty(leg, pin_force_p99_n=20.0)
    frame = Frame()
    beams_kg = 6 * BEAM_KG_PER_MODULE * (1.0 + 10.0)  # six legs of 11 modules of beam
    load = (frame.mass_kg + beams_kg) * 9.81 / 3
    assert found.foot_load_n == pytest.approx(load, rel=1e-9) == foot_load_n(frame, leg)
    reach_mm, offset_mm = 88.0, 16.0  # 11 modules; the foot two layers out
    splay = load * offset_mm * reach_mm**2 / (2 * ABS_E_N_MM2 * I_OUT_MM4) + PIN_PLAY_RAD * reach_mm
    assert found.splay_mm == pytest.approx(splay, rel=1e-9)
    # the foot hangs on its beam past the beam's one pin (node 1): a cantilever of 10
    # modules (80 mm) loaded at its tip in the plane
    assert found.sag_mm == pytest.approx(load * 80.0**3 / (3 * ABS_E_N_MM2 * I_IN_MM4), rel=1e-9)
    assert found.foot_deflection_mm == pytest.approx(math.hypot(found.splay_mm, found.sag_mm))
    assert found.pin_moment_nmm == pytest.approx(20.0 * 16.0)  # 20 N across two layers
    # what beam theory says of the parts: the splay's bending goes with the offset and the
    # square of the reach, the sag with the cube of the overhang
    flat = frailty(hand_leg(reach=11.0, extension=10.0, layers=(0, 0)), 20.0)
    assert flat.splay_mm == 0.0 and flat.pin_moment_nmm == 0.0
    heavier = frailty(leg, 20.0, Frame(mass_kg=2 * frame.mass_kg + beams_kg))
    assert heavier.sag_mm == pytest.approx(2 * found.sag_mm, rel=1e-9)


def test_a_short_leg_is_sound_and_a_long_one_frail():
    short = frailty(hand_leg(reach=5.0, extension=4.0, layers=(0, 1)), 10.0)
    long = frailty(hand_leg(reach=26.0, extension=25.0, layers=(0, 3)), 10.0)
    assert not short.frail and short.reason() == ""
    assert long.frail and long.foot_deflection_mm > FRAIL_FOOT_MM
    assert long.reason().startswith("frail: the foot gives")


def test_the_walk_breaks_a_frail_leg_and_reports_its_figures():
    benchmark = json.loads((ROOT / "benchmarks" / "walk_linkage.json").read_text())
    frail_leg = leg_from_genome(*from_document(benchmark))
    walked = walk(frail_leg, FLOORS["flat"], settings=WalkSettings(seconds=1.0))
    assert walked.frailty is not None and walked.frailty.frail
    assert walked.breaks and "frail: the foot gives" in walked.reason
    assert walked.distance_m > 0.01  # it walks, rigid; the real leg would fold
    sound = json.loads((ROOT / "tests" / "data" / "sound_leg.json").read_text())
    walked = walk(
        leg_from_genome(*from_document(sound)), FLOORS["flat"], settings=WalkSettings(seconds=1.0)
    )
    assert walked.frailty is not None and not walked.frailty.frail and not walked.breaks
    expected = frailty(leg_from_genome(*from_document(sound)), walked.pin_force_n[2])
    assert walked.frailty == expected
