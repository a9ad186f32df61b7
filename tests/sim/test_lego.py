"""Tests the LEGO build: whole-module beams, exact kinematics, the closest path, refusal."""

from __future__ import annotations

import itertools
import math
import re

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.robot.lego import QuantiseError, quantise


@pytest.fixture(scope="module")
def valid_genomes() -> np.ndarray:
    genomes = sim.random_genomes(np.random.default_rng(17), 2000)
    return genomes[sim.evaluate(genomes).error == 0][:12]


def test_every_beam_is_whole_and_no_beam_stretches(valid_genomes):
    for genome in valid_genomes:
        q = quantise(genome)
        assert q.lengths.dtype == np.int64 and (q.lengths >= 1).all()
        assert (np.abs(q.lengths - q.original) < 1).all()
        np.testing.assert_array_equal(q.batch.beam_length[0, : len(q.lengths)], q.lengths)
        assert q.batch.node_float[0, 4, 0] == q.lengths[0]  # the crank
        assert q.motion.valid.all()
        pos = q.motion.positions[0]
        for b, length in enumerate(q.lengths):  # rigid beams at every angle, checked directly
            s, e = q.batch.beam_int[0, b, :2]
            spans = np.hypot(*(pos[e] - pos[s]).T)
            np.testing.assert_allclose(spans, length, rtol=0, atol=1e-9)
        assert q.checks.turns_fully[0] and q.checks.max_stretch[0] <= 1e-9


def test_the_chosen_rounding_keeps_the_path_closest(valid_genomes):
    genome = min(valid_genomes, key=lambda g: int(sim.decode(g[None]).n_beams[0]))
    q = quantise(genome, n_angles=24)
    base = sim.decode(genome[None])
    original = q.original
    best = math.inf
    for choice in itertools.product(
        *[sorted({max(math.floor(v), 1), max(math.ceil(v), 1)}) for v in original]
    ):
        other = quantise_fixed(genome, np.array(choice))
        if other is not None:
            best = min(best, other)
    assert q.mean_shift == pytest.approx(best, abs=1e-12)
    assert base.n_beams[0] == len(q.lengths)


def quantise_fixed(genome: np.ndarray, lengths: np.ndarray) -> float | None:
    """The mean foot-path shift of one given rounding, or None when it is not exact."""
    from linkevo.sim.robot.lego import _with_lengths

    base = sim.decode(genome[None])
    one = _with_lengths(base, lengths[None])
    motion = sim.simulate(one, 24)
    if not motion.valid.all():
        return None
    pos = motion.positions[0]
    for b, length in enumerate(lengths):
        s, e = one.beam_int[0, b, :2]
        if np.abs(np.hypot(*(pos[e] - pos[s]).T) - length).max() > 1e-9:
            return None
    here = sim.simulate(base, 24)
    foot = here.positions[0, here.foot[0]]
    built = pos[motion.foot[0]]
    return float(np.mean(np.hypot(*(built - foot).T)))


def test_the_loss_is_the_specs_as_evolved_and_as_built(valid_genomes):
    genome = valid_genomes[0]
    q = quantise(genome, fitness="Fsl")
    assert q.original_loss == pytest.approx(float(sim.evaluate(genome[None], "Fsl").loss[0]))
    assert math.isfinite(q.loss)


def test_a_linkage_no_rounding_turns_is_refused_with_the_reason():
    genomes = sim.random_genomes(np.random.default_rng(2), 400)
    errors = sim.evaluate(genomes).error
    stuck = genomes[errors >= 30][:20]  # fails at most crank angles
    refused = []
    for genome in stuck:
        try:
            quantise(genome)
        except QuantiseError as exc:
            refused.append(str(exc))
    assert refused, "no linkage was refused"
    assert re.fullmatch(
        r"no whole-module rounding of the \d+ beams turns fully with rigid beams: of \d+ "
        r"roundings \(each length down or up\), \d+ turn fully in simulation and the least "
        r"stretch among them is (nan|[\d.]+) modules",
        refused[0],
    )
