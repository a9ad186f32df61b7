"""What a builder should doubt in a walking search's winner: the leg's shape (size, stroke,
crank share), walks beyond the level-body bound or on sliding feet, and the full model's
confirmation of the lean model's walk."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from linkevo.sim.robot.confirmation import confirm_walk
from linkevo.sim.robot.hexapod import FLOORS, UNIT_M
from linkevo.sim.robot.walk_rows import (
    COLUMNS,
    Status,
    beyond_bound_share,
    credited_cm,
    map_row,
    slide_share,
    walked_row,
)
from linkevo.sim.robot.walking import WalkSettings, walk
from linkevo.workers.store.artifacts import write_parquet_atomic
from linkevo.workers.store.tables import read_walk_map
from linkevo.workers.walk_log import WalkLog
from tests.helpers.walking import crank_leg, jansen_leg


def test_a_foot_on_the_crank_has_a_crank_share_of_one_and_jansens_far_less():
    wheel, jansen = crank_leg(8.0), jansen_leg()
    assert wheel.crank_share() == pytest.approx(1.0, abs=1e-9)
    assert jansen.crank_share() < 0.2  # its foot is pushed along a flat stance
    shape = jansen.shape()
    cm = UNIT_M * 100
    assert shape["size_cm"][0] == pytest.approx(np.ptp(jansen.paths[..., 0]) * cm, abs=0.05)
    assert shape["stroke_cm"] == pytest.approx(jansen.stance_stroke() * cm, abs=0.05)
    assert wheel.shape()["lift_cm"] == pytest.approx(16 * cm, abs=0.05)  # the rim's diameter


def test_sliding_and_the_excess_over_the_bound_are_shares_of_the_walk():
    base = {"cell": 3, "seconds": 10.0}
    row = map_row(base, "flat", Status.WALKED, distance=50.0, bound=40.0, slip=30.0)
    assert slide_share(row) == pytest.approx(30.0 / 50.0)  # body: 50 cm / 10 s = 50 mm/s
    assert beyond_bound_share(row) == pytest.approx(0.25)
    within = map_row(base, "flat", Status.WALKED, distance=30.0, bound=40.0)
    assert beyond_bound_share(within) == 0.0 and math.isnan(slide_share(within))
    backwards = map_row(base, "flat", Status.WALKED, distance=-5.0, bound=40.0, slip=3.0)
    assert math.isnan(slide_share(backwards))


def test_an_older_walk_map_and_walk_log_read_the_later_columns_as_unknown(tmp_path):
    row = map_row({"cell": 7, "seconds": 10.0}, "flat", Status.WALKED, distance=20.0, bound=30.0)
    old = {c: np.array([row[c]]) for c in COLUMNS if c != "foot_slip_mm_s"}
    write_parquet_atomic(tmp_path / "walkmap.parquet", old)
    frame = read_walk_map(tmp_path / "walkmap.parquet", "r1")
    assert math.isnan(frame["foot_slip_mm_s"].iloc[0]) and frame["cell"].iloc[0] == 7
    log = WalkLog.empty()
    state = {k: v for k, v in log.state_dict().items() if not k.endswith("foot_slip_mm_s")}
    assert WalkLog.from_state(state).floors["flat"]["foot_slip_mm_s"].shape == (0,)


def test_the_full_model_confirms_a_sound_walker_and_reports_its_shape():
    leg = jansen_leg()
    seconds = 3.0
    lean = {}
    for floor in ("flat", "carpet"):
        w = walk(leg, FLOORS[floor], settings=WalkSettings(seconds=seconds))
        lean[floor] = credited_cm(walked_row({"cell": -1, "seconds": seconds}, floor, w, ""))
    checked = confirm_walk(leg, lean, repeats=2, seconds=seconds)
    assert checked.agrees and not checked.slides
    found = checked.as_dict()
    assert found["shape"] == leg.shape()
    for floor in ("flat", "carpet"):
        f = found["floors"][floor]
        assert f["slide_share"] is not None and 0 <= f["slide_share"] < 0.5
        assert f["beyond_bound_share"] == 0.0  # Jansen's flat stance walks within its bound
        assert f["lean_cm"] == pytest.approx(lean[floor], abs=0.01)
    assert pd.Series(found["floors"]["flat"]["full_cm"]).notna().all()
