"""Tests `sim.robot.builds`: the whole batch's LEGO builds found by the depth-first search agree
with the exhaustive closest rounding (`sim.robot.lego.closest_build`), turn rigidly, stand in
as evolved where none is found, and are the build every leg is made of (one linkage's
`whole_module_build`, a walk given its batch's build); `with_lengths` writes lengths as
decoding does; the tripod features by hand."""

from __future__ import annotations

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.linkage.decoding import NODE_KINDS, with_lengths
from linkevo.sim.linkage.kinematics import simulate
from linkevo.sim.linkage.physical import max_stretch, physical_checks
from linkevo.sim.robot.builds import build_lengths, lego_builds
from linkevo.sim.robot.leg import recipe_and_leg
from linkevo.sim.robot.lego import QuantiseError, closest_build, whole_module_build
from linkevo.sim.robot.walk_features import _tripod


@pytest.fixture(scope="module")
def turning() -> np.ndarray:
    """80 random linkages (80, 56) that turn fully."""
    genomes = sim.random_genomes(np.random.default_rng(5), 6000)
    return genomes[sim.evaluate(genomes).error == 0][:80]


def test_the_builds_are_quantises_and_turn_rigidly(turning):
    batch = sim.decode(turning)
    built_batch, built = lego_builds(batch)
    agree = 0
    for i, genome in enumerate(turning):
        k = int(batch.n_beams[i])
        try:
            exact = closest_build(genome).beam_length[0, :k]
        except QuantiseError:
            exact = None
        lengths = built_batch.beam_length[i, :k]
        if built[i]:
            assert (lengths == np.round(lengths)).all() and (lengths >= 1).all()
            assert (np.abs(lengths - batch.beam_length[i, :k]) < 1).all()
        else:  # none found: the linkage as evolved stands in
            np.testing.assert_array_equal(lengths, batch.beam_length[i, :k])
        agree += exact is not None and built[i] and np.array_equal(lengths, exact)
        agree += exact is None and not built[i]
    assert agree >= 0.95 * len(turning)
    motion = simulate(built_batch)
    assert motion.valid[built].all()
    assert (max_stretch(built_batch, motion)[built] <= 1e-9).all()
    # the checks take a rigid build's stretch as 0 and measure the others as ever
    told, measured = (
        physical_checks(built_batch, motion, rigid=built),
        physical_checks(built_batch, motion),
    )
    np.testing.assert_allclose(told.max_stretch, measured.max_stretch, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(told.size_modules, measured.size_modules)


def test_every_leg_is_built_as_its_batch_is(turning):
    """One linkage's build is its batch's, and a leg built from the batch's lengths is the
    leg built from its genome alone (the same key: a walk's cache and `linkevo pull` agree)."""
    batch = sim.decode(turning[:20])
    built_batch, built = lego_builds(batch)
    searched = build_lengths(batch)
    assert built.all()
    for i, genome in enumerate(turning[:20]):
        np.testing.assert_array_equal(
            whole_module_build(genome).beam_length[0, : batch.n_beams[i]],
            built_batch.beam_length[i, : batch.n_beams[i]],
        )
        alone, _ = recipe_and_leg(genome)
        given, _ = recipe_and_leg(genome, searched=searched[i])
        assert given.key == alone.key and given.note == alone.note


def test_with_lengths_writes_them_as_decoding_does(turning):
    batch = sim.decode(turning)
    again = with_lengths(batch, batch.beam_length)
    np.testing.assert_array_equal(again.node_float, batch.node_float)
    # every triangle with equal whole lengths gets decoding's backup point, the others none
    equal = np.full_like(batch.beam_length, 2.0)
    node_float = with_lengths(batch, equal).node_float
    triangle = batch.node_int[:, :, 0] == NODE_KINDS.index("triangle")
    angle = batch.node_float[..., 2]
    np.testing.assert_array_equal(node_float[..., 3][triangle], (2 * np.cos(angle))[triangle])
    np.testing.assert_array_equal(node_float[..., 4][triangle], (2 * np.sin(angle))[triangle])


def test_a_tripod_gait_by_hand():
    """A foot that pushes a flat stroke of 4 modules for half the turn and lifts (at least
    0.2 modules) for the other half: two tripods half a turn apart carry the body by turns
    at one height, so it advances two strokes per turn without bobbing or stepping back,
    and both feet are within 0.25 modules only at the two hand-overs."""
    a = 40
    t = np.arange(a) / a
    down = t < 0.5
    x = np.where(down, -2 + 8 * t, 2 - 8 * (t - 0.5))  # along the stroke, then back
    y = np.where(down, 0.0, 0.2 + np.sin(2 * np.pi * (t - 0.5)))  # flat, then lifted
    advance, bob, both_down, backwards, drop = (v[0] for v in _tripod(x[None], y[None]))
    assert advance == pytest.approx(8.0)
    assert bob == pytest.approx(0.0) and backwards == pytest.approx(0.0)
    assert both_down == pytest.approx(2 / a)
    assert drop == pytest.approx(0.0)
