"""Classic mechanisms move as mechanics says, in the reference and in the kernel."""

from __future__ import annotations

import math

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.linkage import reference

T = reference.TOLERANCE
ANGLES = np.arange(40) * 2.0 * math.pi / 40


def four_bar(builder, pivot: tuple[int, int], crank: float, coupler: float, rocker: float, mode):
    """Returns the genome of motor -> crank -> coupler -> rocker -> static `pivot`.

    Node 5 is the coupler-rocker joint: l1 = coupler from the crank tip (node 4), l2 = rocker
    from the static pivot (node 1).
    """
    b = builder(statics=(pivot, (-5, 5), (5, 5)), crank=crank, mode=mode)
    b.triangle(4, 1, coupler, rocker, direction=0)
    return b.genome()


@pytest.mark.parametrize("mode", sim.MODES)
def test_grashof_crank_rocker_turns_fully_and_keeps_its_links(builder, mode):
    ground, crank, coupler, rocker = 4.0, 2.0, 5.0, 4.0
    links = sorted([ground, crank, coupler, rocker])
    assert links[0] + links[3] <= links[1] + links[2] and links[0] == crank  # Grashof
    genome = four_bar(builder, (-4, 0), crank, coupler, rocker, mode)
    motion = reference.simulate_linkage(reference.decode_linkage(genome, mode))
    assert motion.valid.all()
    tip = np.c_[crank * np.cos(ANGLES), crank * np.sin(ANGLES)]
    joint = motion.positions[5]
    pivot = np.array([-4.0, 0.0])
    np.testing.assert_allclose(motion.positions[4], tip, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(joint - tip, axis=1), coupler, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(joint - pivot, axis=1), rocker, atol=1e-9)
    # One assembly branch throughout: the joint stays on the same side of tip -> pivot.
    u, v = pivot - tip, joint - tip
    side = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    assert (np.sign(side) == np.sign(side[0])).all()
    # The rocker only rocks: its angle sweeps less than half a turn.
    rocker_angle = np.unwrap(np.arctan2(joint[:, 1], joint[:, 0] + 4.0))
    assert np.ptp(rocker_angle) < math.pi
    kernel = sim.simulate(sim.decode(genome[None], mode))
    assert kernel.valid.all()
    np.testing.assert_allclose(kernel.positions[0, 5], joint, atol=1e-9)


@pytest.mark.parametrize("mode", sim.MODES)
def test_non_grashof_four_bar_fails_exactly_where_loop_closure_forbids(builder, mode):
    ground, crank, coupler, rocker = 4.0, 3.0, 3.0, 3.6
    links = sorted([ground, crank, coupler, rocker])
    assert links[0] + links[3] > links[1] + links[2]  # non-Grashof
    genome = four_bar(builder, (4, 0), crank, coupler, rocker, mode)
    # Distance crank tip -> pivot at each angle; the loop closes when it is within
    # [|coupler - rocker|, coupler + rocker], widened by circle_intersection's tolerance.
    d = np.hypot(crank * np.cos(ANGLES) - ground, crank * np.sin(ANGLES))
    too_far = d - T - (coupler + rocker)
    too_near = abs(coupler - rocker) - (d + T)
    assert min(np.abs(too_far).min(), np.abs(too_near).min()) > 1e-3  # no angle on a boundary
    expected_valid = (too_far <= 0) & (too_near <= 0)
    in_band = expected_valid & (d > coupler + rocker)
    assert in_band.sum() >= 2  # the tolerance band admits angles a strict test would reject
    assert list(np.flatnonzero(~expected_valid)) == list(range(17, 24))
    motion = reference.simulate_linkage(reference.decode_linkage(genome, mode))
    np.testing.assert_array_equal(motion.valid, expected_valid)
    assert motion.error == 7
    assert np.isnan(motion.positions[:, ~expected_valid]).all()
    kernel = sim.simulate(sim.decode(genome[None], mode))
    np.testing.assert_array_equal(kernel.valid[0], expected_valid)


def test_chebyshev_lambda_traces_a_straight_stance_line(builder):
    """Chebyshev's lambda, scaled x2: ground 4, crank 2, coupler 5, rocker 5, foot 10 from
    the crank tip along the coupler. Over half a crank turn (21 of 40 samples) the point
    stays within 0.02 units (0.16 mm) of a horizontal line while travelling 8 units."""
    b = builder(statics=((-4, 0), (-5, 5), (5, 5)), crank=2.0)
    joint = b.triangle(4, 1, 5.0, 5.0, direction=0)
    point = b.extension(1, 5.0)  # beam 1 is crank tip -> joint, the coupler
    genome = b.genome()
    motion = reference.simulate_linkage(reference.decode_linkage(genome, "paper"))
    assert motion.valid.all()
    path = motion.positions[point]
    tip = motion.positions[4]
    np.testing.assert_allclose(path - tip, 2.0 * (motion.positions[joint] - tip), atol=1e-9)
    stance = np.r_[30:40, 0:11]  # crank angles -90 deg .. +90 deg
    line = np.polyfit(path[stance, 0], path[stance, 1], 1)
    deviation = path[stance, 1] - np.polyval(line, path[stance, 0])
    assert np.abs(deviation).max() < 0.02
    assert abs(line[0]) < 1e-3  # parallel to the ground link
    assert np.ptp(path[stance, 0]) > 7.9
    # The stance is the bottom of the path and the swing rises well above it.
    assert path[stance, 1].max() < path[:, 1].min() + 0.02
    assert np.ptp(path[:, 1]) > 1.7
    kernel = sim.simulate(sim.decode(genome[None], "paper"))
    np.testing.assert_allclose(kernel.positions[0, point], path, atol=1e-9)
