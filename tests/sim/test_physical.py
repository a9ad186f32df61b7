"""Tests the physical checks against a plain per-linkage, per-angle computation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.linkage.physical import BUILDABLE_STRETCH, TOGGLE_DEG, physical_checks


def plain_checks(batch: sim.LinkageBatch, motion: sim.Motion, i: int) -> dict:
    """The checks of linkage i, one beam, joint and angle at a time."""
    pos, valid = motion.positions[i], motion.valid[i]
    stretch, transmissions, toggles = [], [], 0
    for k in np.flatnonzero(valid):
        for b in range(int(batch.n_beams[i])):
            s, e = batch.beam_int[i, b, :2]
            span = math.dist(pos[s, k], pos[e, k])
            stretch.append(abs(span - batch.beam_length[i, b]))
        at_k = []
        for j in range(12):
            if batch.node_int[i, j, 0] == 3:  # triangle
                a, c = batch.node_int[i, j, 1:3]
                u, v = pos[a, k] - pos[j, k], pos[c, k] - pos[j, k]
                t = math.degrees(
                    math.acos(max(-1, min(1, np.dot(u, v) / math.hypot(*u) / math.hypot(*v))))
                )
                at_k.append(min(t, 180 - t))
        transmissions += at_k
        toggles += bool(at_k) and min(at_k) < TOGGLE_DEG
    points = pos[:, valid].reshape(-1, 2)
    return {
        "turns_fully": bool(valid.all()),
        "max_stretch": max(stretch) if stretch else math.nan,
        "min_transmission_deg": (min(transmissions) if transmissions else 90.0)
        if valid.any()
        else math.nan,
        "toggle_passages": toggles,
        "size": (points.max(0) - points.min(0)) if valid.any() else (math.nan, math.nan),
    }


@pytest.mark.parametrize("mode", ["paper", "legacy"])
def test_the_checks_equal_a_plain_computation(mode):
    genomes = sim.random_genomes(np.random.default_rng(41), 300)
    batch = sim.decode(genomes, mode)
    motion = sim.simulate(batch, 24)
    checks = physical_checks(batch, motion)
    assert checks.turns_fully.tolist() == (motion.error == 0).tolist()
    for i in range(len(genomes)):
        want = plain_checks(batch, motion, i)
        assert checks.turns_fully[i] == want["turns_fully"]
        np.testing.assert_allclose(checks.max_stretch[i], want["max_stretch"], atol=1e-12)
        np.testing.assert_allclose(
            checks.min_transmission_deg[i],
            want["min_transmission_deg"],
            atol=1e-5,  # arccos near 1: 1e-16 in cos is 1e-6 degrees
        )
        assert checks.toggle_passages[i] == want["toggle_passages"]
        np.testing.assert_allclose(checks.size_modules[i], want["size"], atol=1e-12)


def test_buildable_needs_a_full_turn_no_toggle_and_no_stretch():
    genomes = sim.random_genomes(np.random.default_rng(5), 3000)
    batch = sim.decode(genomes)
    checks = physical_checks(batch, sim.simulate(batch))
    assert checks.buildable.any() and not checks.buildable.all()
    good = checks.buildable
    assert checks.turns_fully[good].all() and (checks.toggle_passages[good] == 0).all()
    assert (checks.max_stretch[good] <= BUILDABLE_STRETCH).all()
    stretched = checks.turns_fully & (checks.max_stretch > 0.5)
    assert stretched.any() and not checks.buildable[stretched].any()  # the tolerance band at work
    row = checks.row(int(np.flatnonzero(good)[0]))
    assert row["buildable"] is True and row["width_modules"] > 0
