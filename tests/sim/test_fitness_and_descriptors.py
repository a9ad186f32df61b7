"""Fitness and descriptor definitions (spec §4-5, docs/simulator.md) on hand-made inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.linkage import reference

D16_ARC_Y = [1.26875, 2.26875, 2.76875, 2.96875, 2.76875, 2.26875, 1.26875]
D24_ARC_Y = [1.196875, 1.696875, 1.946875, 2.046875, 1.946875, 1.696875, 1.196875]


@pytest.mark.parametrize(
    ("name", "bottom_x", "bottom_y", "arc_x", "arc_y"),
    [
        ("D16", np.arange(-8, 9, 2), -1.73125, np.arange(-6, 7, 2), D16_ARC_Y),
        ("D24", np.arange(-12, 13, 3), -1.303125, np.arange(-9, 10, 3), D24_ARC_Y),
    ],
)
def test_named_targets_match_the_spec_table(name, bottom_x, bottom_y, arc_x, arc_y):
    target = sim.named_target(name)
    expected = np.r_[np.c_[bottom_x, np.full(9, bottom_y)], np.c_[arc_x, arc_y]]
    np.testing.assert_allclose(target.points, expected, rtol=0, atol=1e-12)
    assert target.is_step.tolist() == [True] * 9 + [False] * 7


def test_path_shaped_like_the_target_has_zero_distance_wherever_it_is():
    target = sim.named_target("D16")
    path = target.points + np.array([13.0, -7.5])
    step, lift = reference.target_distances(path, target)
    assert step == pytest.approx(0.0, abs=1e-12) and lift == pytest.approx(0.0, abs=1e-12)


def test_single_point_path_is_compared_at_its_centroid():
    target = sim.named_target("D16")
    step, lift = reference.target_distances(np.array([[4.0, -3.0]]), target)
    norms = np.linalg.norm(target.points, axis=1)
    assert step == pytest.approx(norms[target.is_step].sum(), abs=1e-12)
    assert lift == pytest.approx(norms[~target.is_step].sum(), abs=1e-12)


def rectangle_path() -> np.ndarray:
    """A 4 x 2 loop: stance along y = 0 moving +x, swing back along y = 2 moving -x."""
    bottom = [(x, 0.0) for x in range(5)]
    up = [(4.0, 1.0), (4.0, 2.0)]
    top = [(x, 2.0) for x in range(3, -1, -1)]
    return np.array([*bottom, *up, *top, (0.0, 1.0)], dtype=float)


def test_step_and_lift_of_a_rectangular_loop():
    step, lift = reference.step_and_lift(rectangle_path())
    assert step == 4.0 and lift == 2.0


def test_step_and_lift_follow_the_stance_direction_of_the_lowest_sample():
    # Traversed backwards the stance moves -x; the numbers are the same.
    step, lift = reference.step_and_lift(rectangle_path()[::-1])
    assert step == 4.0 and lift == 2.0
    # The contact band is 0.5 high: lifting two stance samples by 0.6 shortens the stance.
    path = rectangle_path()
    path[[3, 4], 1] = 0.6
    step, _ = reference.step_and_lift(path)
    assert step == 2.0


def test_step_and_lift_of_a_single_sample_are_zero():
    assert reference.step_and_lift(np.array([[1.0, 2.0]])) == (0.0, 0.0)


@pytest.mark.parametrize("mode", sim.MODES)
def test_losses_combine_the_parts_as_the_spec_says(mode, random_set):
    for genome in random_set[:40]:
        linkage = reference.decode_linkage(genome, mode)
        motion = reference.simulate_linkage(linkage)
        penalty = motion.error + reference.angle_error(motion, mode)
        step_d, lift_d = reference.target_distances(motion.foot_path, sim.named_target())
        f_s, f_l = reference.step_and_lift(motion.foot_path)
        target = sim.named_target()
        assert reference.losses(motion, "Fp", mode, target) == [step_d + lift_d + penalty]
        assert reference.losses(motion, "Fp2", mode, target) == [
            step_d + penalty,
            lift_d + penalty,
        ]
        assert reference.losses(motion, "Fsl", mode, target) == [-0.8 * f_s - 0.2 * f_l + penalty]
        assert reference.losses(motion, "Fsl2", mode, target) == [
            -f_s + penalty,
            -f_l + penalty,
        ]


def test_structural_descriptors_of_a_chebyshev_lambda(builder):
    b = builder(statics=((-4, 0), (-5, 5), (5, 5)), crank=2.0)
    joint = b.triangle(4, 1, 5.0, 5.0, direction=1)  # node 5: anchors crank tip and node 1
    foot = b.extension(1, 5.0)  # node 6: continues beam 1 (crank tip -> joint)
    genome = b.genome()
    linkage = reference.decode_linkage(genome, "paper")
    parents = reference.decode_graph_parents(linkage)
    assert parents[4] == [0] and parents[joint] == [4, 1] and parents[foot] == [4, joint]
    # depth: tip 1, joint 2, foot 3; drive: {0, 1, 4, 5, 6}; moving: {4, 5, 6}.
    assert reference.structure_descriptors(linkage, foot) == (3.0, 5.0, 3 / 5)
    ev = reference.evaluate_reference(genome[None])
    kernel = sim.evaluate(genome[None])
    assert ev.foot[0] == kernel.foot[0] == foot
    # Beams: crank 2, l1 5, l2 5, extension 5, then five filler triangles (8.5 and 8.25).
    lengths = [2.0, 5.0, 5.0, 5.0] + [8.5, 8.25] * 5
    m = float(np.mean([(x - 2.0) * 10.0 / 13.0 for x in lengths]))
    expected_st = [m, 3.0 * 10.0 / 9.0, 5.0 * 10.0 / 13.0, 6.0]
    np.testing.assert_allclose(ev.descriptors["MAP-ST"][0], expected_st, atol=1e-12)
    np.testing.assert_allclose(kernel.descriptors["MAP-ST"][0], expected_st, atol=1e-9)
    path = np.c_[ev.foot_x[0], ev.foot_y[0]]
    height, width = np.ptp(path[:, 1]), np.ptp(path[:, 0])
    assert height == pytest.approx(math.sqrt(96) - 8.0, abs=1e-9)  # 9.798 - 8
    np.testing.assert_allclose(ev.descriptors["MAP-WH"][0], [height, width], atol=1e-12)
    _, lift = reference.step_and_lift(path)
    np.testing.assert_allclose(ev.descriptors["MAP-LIS"][0], [m, lift], atol=1e-12)


def test_static_foot_has_depth_zero_and_no_moving_share(builder):
    # Statics low, so static node 1 at (0, -5) is the lowest point of the linkage.
    b = builder(statics=((0, -5), (-5, 5), (5, 5)), crank=2.0)
    genome = b.genome()
    for evaluate in (sim.evaluate, reference.evaluate_reference):
        ev = evaluate(genome[None])
        assert ev.foot[0] == 1 and ev.angle_error[0] == 0.0
        np.testing.assert_allclose(ev.descriptors["MAP-ST"][0, 1:], [0.0, 10.0 / 13.0, 0.0])
        np.testing.assert_allclose(ev.descriptors["MAP-WH"][0], [0.0, 0.0])
