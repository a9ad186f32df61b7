"""The walking fitness on the real engine: a walk stopped at its break breaks as the whole
walk does, a sound walk is the walk map's walk, the floors' losses fall in their tiers,
and a floor that cannot matter is not walked."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from linkevo.sim.linkage.linkage_doc import from_document
from linkevo.sim.linkage.physical import PhysicalChecks
from linkevo.sim.robot.hexapod import FLOORS
from linkevo.sim.robot.walk_fitness import (
    BROKEN_LOSS,
    NO_LEG_LOSS,
    REJECTED_LOSS,
    floor_losses,
    rejected_loss,
    walk_candidate,
)
from linkevo.sim.robot.walk_map import CellBatch, walk_cells, walk_map_settings
from linkevo.sim.robot.walk_rows import WALK_ORDER
from linkevo.sim.robot.walking import walk
from tests.helpers.walking import crank_leg

SOUND_LEG = Path(__file__).parents[1] / "data" / "sound_leg.json"


@pytest.fixture(scope="module")
def genome() -> np.ndarray:
    """A sound leg's linkage (MAP-WH/Fp/07's best of the paper-mode study grid: it walks
    on both floors without breaking, frailty well under the limits)."""
    return from_document(json.loads(SOUND_LEG.read_text()))[0]


def row(status="walked", distance=50.0, breaks=False, bound=100.0, floor="flat") -> dict:
    return {
        "floor": floor,
        "status": status,
        "mean_distance_cm": distance,
        "breaks": breaks,
        "bound_cm": bound,
        "seconds": 10.0,
    }


def test_a_walk_stopped_at_its_break_breaks_as_the_whole_walk_does():
    leg = crank_leg(2.0)  # a spoke too short to lift the frame: it drags from the start
    settings = walk_map_settings(4.0)
    whole = walk(leg, FLOORS["flat"], settings=settings)
    stopped = walk(leg, FLOORS["flat"], settings=dataclasses.replace(settings, stop_at_break=True))
    assert whole.breaks and stopped.breaks
    assert math.isnan(whole.stopped_s) and stopped.stopped_s < 4.0
    assert whole.reason.split(":")[0] == stopped.reason.split(":")[0]  # the same rule
    assert f"stopped at {stopped.stopped_s:.1f} s of 4" in stopped.reason


def test_a_sound_walk_is_the_walk_maps_walk_on_both_floors(genome):
    walked = walk_candidate(genome, "paper", seconds=3.0)
    assert walked.stage == "walked" and len(walked.key) == 40
    assert [r["floor"] for r in walked.rows] == list(WALK_ORDER)
    mapped = walk_cells(CellBatch(np.array([7]), genome[None], "paper", WALK_ORDER, seconds=3.0))
    for mine, theirs in zip(walked.rows, mapped, strict=True):
        assert not mine["breaks"] and mine["mean_distance_cm"] > 10.0
        assert mine == {**theirs, "cell": -1}
    losses = floor_losses("walked", {r["floor"]: r for r in walked.rows})
    per_10_s = [min(r["mean_distance_cm"], r["bound_cm"]) * 10 / 3 for r in walked.rows]
    np.testing.assert_allclose(sorted(-losses), sorted(per_10_s), rtol=1e-12)


def test_a_floor_that_cannot_matter_is_not_walked(genome):
    kept_out = walk_candidate(genome, "paper", bar=-1e6, seconds=3.0)  # nothing gets below
    carpet, flat = kept_out.rows
    assert carpet["status"] == "walked" and flat["status"] == "not walked"
    assert not flat["breaks"] and "keeps it out" in flat["reason"]
    losses = floor_losses("walked", {r["floor"]: r for r in kept_out.rows})
    per_10_s = min(carpet["mean_distance_cm"], carpet["bound_cm"]) * 10 / 3
    assert losses[0] == losses[1] == pytest.approx(-per_10_s, rel=1e-12)
    known = walk_candidate(genome, "paper", known={kept_out.key}, seconds=3.0)
    assert known.stage == "cached" and known.rows == () and known.key == kept_out.key


def test_the_floors_losses_fall_in_their_tiers():
    both = {"flat": row(distance=80.0), "carpet": row(distance=60.0, floor="carpet")}
    assert floor_losses("walked", both).tolist() == [-80.0, -60.0]
    beyond = {"flat": row(distance=150.0, bound=120.0), "carpet": row(floor="carpet")}
    assert floor_losses("walked", beyond)[0] == -120.0  # credited at most its bound
    broke = {
        "carpet": row(distance=20.0, breaks=True, floor="carpet"),
        "flat": row(status="not walked", distance=math.nan, breaks=True),
    }
    assert floor_losses("walked", broke).tolist() == [BROKEN_LOSS - 20.0] * 2
    diverged = {
        "carpet": row(distance=math.nan, breaks=True, floor="carpet"),
        "flat": row(status="not walked", distance=math.nan, breaks=True),
    }
    assert floor_losses("walked", diverged).tolist() == [BROKEN_LOSS] * 2
    for stage in ("no_lego_build", "no_turn", "failed"):
        assert floor_losses(stage, {}).tolist() == [NO_LEG_LOSS] * 2
    checks = PhysicalChecks(
        turns_fully=np.array([False, True, True]),
        min_transmission_deg=np.array([30.0, 2.0, 40.0]),
        toggle_passages=np.array([0, 3, 0]),
        max_stretch=np.array([np.nan, 0.0, 0.5]),
        size_modules=np.zeros((3, 2)),
    )
    graded = rejected_loss(np.array([12, 0, 0]), checks)
    assert graded.tolist() == [REJECTED_LOSS + 13, REJECTED_LOSS + 3, REJECTED_LOSS + 1]
    assert graded.min() > NO_LEG_LOSS > BROKEN_LOSS - 300.0 > 0.0  # the tiers never overlap


def test_caveats_name_what_a_builder_should_doubt():
    from dataclasses import replace

    from linkevo.sim.robot.field_summary import caveats
    from linkevo.sim.robot.walking import Walk

    plain = Walk(
        distance_m=0.5,
        bound_m=1.0,
        heading_drift_deg=0.0,
        body_height_m=0.1,
        clearance_m=0.05,
        max_pitch_deg=5.0,
        max_roll_deg=2.0,
        foot_slip_mm_s=1.0,
        torque_p95=0.3,
        torque_max=0.5,
        saturated=np.zeros(6),
        max_lag_deg=3.0,
        pin_force_n=(1.0, 2.0, 3.0, 4.0),
        loop_error_mm=0.01,
        frame_contact=0.0,
        breaks=False,
        reason="",
        trace={},
        foot_deviation_mm=0.1,
    )
    assert caveats([plain]) == []
    near, far = replace(plain, distance_m=0.98), replace(plain, distance_m=1.02)
    assert "1 of 2 walks go beyond the level-body bound (100 cm)" in caveats([near, far])[0]
    scattered = caveats([plain, replace(plain, distance_m=0.9)])
    assert "a chaotic gait: the repeats walk 50 to 90 cm" in scattered[0]
    assert "pitches up to 31°" in caveats([replace(plain, max_pitch_deg=31.0)])[0]
    assert "feet stray up to 3.8 mm" in caveats([replace(plain, foot_deviation_mm=3.8)])[0]
