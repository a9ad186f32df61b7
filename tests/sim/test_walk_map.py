"""The walk map's protocol on the real engine: one walk per cell and floor ranks cells as
the Table I protocol (five perturbed walks) does, cells that build the same leg share one
walk, and a bad cell is recorded, not fatal."""

from __future__ import annotations

import numpy as np
from scipy.stats import spearmanr

from linkevo.sim.linkage.evaluating import evaluate
from linkevo.sim.linkage.genome import random_genomes
from linkevo.sim.robot.hexapod import FLOORS
from linkevo.sim.robot.leg import LegError, leg_from_genome
from linkevo.sim.robot.walk_map import CellBatch, build_cells, group_legs, walk_cells
from linkevo.sim.robot.walk_rows import COLUMNS
from linkevo.sim.robot.walking import WalkSettings, field_trials

SECONDS = 4.0


def built_genomes(count: int) -> np.ndarray:
    """The `count` lowest-F_p random genomes whose LEGO build turns."""
    genomes = random_genomes(np.random.default_rng(11), 3000)
    found = []
    for i in np.argsort(evaluate(genomes, "Fp", "paper").loss):
        try:
            if leg_from_genome(genomes[i]).built:
                found.append(genomes[i])
        except LegError:
            continue
        if len(found) == count:
            return np.array(found)
    raise AssertionError("too few buildable genomes")


def test_one_walk_per_cell_ranks_cells_as_the_table_one_protocol_does():
    genomes = built_genomes(6)
    rows = walk_cells(CellBatch(np.arange(6), genomes, "paper", ("flat",), seconds=SECONDS))
    assert [r["status"] for r in rows] == ["walked"] * 6
    assert all(set(r) == set(COLUMNS) for r in rows)
    mapped = np.array([r["mean_distance_cm"] for r in rows])
    protocol = np.array(
        [
            np.mean(
                [
                    w.distance_m * 100
                    for w in field_trials(
                        leg_from_genome(g), FLOORS["flat"], settings=WalkSettings(seconds=SECONDS)
                    )
                ]
            )
            for g in genomes
        ]
    )
    assert np.ptp(protocol) > 5.0  # the cells differ, so the ranking means something
    assert spearmanr(mapped, protocol).statistic >= 0.9
    assert np.abs(mapped - protocol).max() < 0.1 * np.abs(protocol).max() + 2.0


def test_a_cell_that_cannot_be_walked_is_recorded_and_the_batch_goes_on():
    genomes = built_genomes(1)
    bad = np.full(56, np.nan)
    rows = walk_cells(
        CellBatch(
            np.array([7, 8]), np.vstack([bad, genomes]), "paper", ("flat", "carpet"), seconds=1.0
        )
    )
    by_cell = {(r["cell"], r["floor"]): r for r in rows}
    assert len(rows) == 4
    for floor in ("flat", "carpet"):
        failed = by_cell[(7, floor)]
        assert failed["status"] == "failed"
        assert "gene 0 is nan" in failed["reason"]
        assert by_cell[(8, floor)]["status"] == "walked"
        assert np.isfinite(by_cell[(8, floor)]["mean_distance_cm"])


def test_cells_that_build_the_same_leg_share_one_walk():
    genome = built_genomes(1)[0]
    nudged = genome + 1e-9  # the same whole-module rounding, another genome
    other = built_genomes(2)[1]
    batch = CellBatch(
        np.array([3, 4, 5]),
        np.vstack([genome, nudged, other]),
        "paper",
        ("flat", "carpet"),
        seconds=1.0,
    )
    legs = group_legs(build_cells(batch))
    assert sorted(sorted(leg.cells) for leg in legs) == [[3, 4], [5]]
    rows = walk_cells(batch)
    assert [(r["cell"], r["floor"]) for r in rows] == [
        (c, f) for c in (3, 4, 5) for f in ("flat", "carpet")
    ]
    by_cell = {(r["cell"], r["floor"]): r for r in rows}
    for floor in ("flat", "carpet"):
        shared = {k: v for k, v in by_cell[(3, floor)].items() if k != "cell"}
        assert shared == {k: v for k, v in by_cell[(4, floor)].items() if k != "cell"}
        assert by_cell[(3, floor)]["status"] == "walked"
        assert by_cell[(5, floor)]["mean_distance_cm"] != by_cell[(3, floor)]["mean_distance_cm"]
