"""F_ae's beam-angle convention (spec §2 "Triangle", §3 "Angle error"): a triangle beam's
recorded angle lies in [0, 2 pi), and the foot points upwards where the arithmetic mean of
its beams' recorded angles lies in (0, pi).

The kernel's F_ae is checked on hand-made foot beams, one configuration per crank sample,
against the rule computed from the reference's `beam_angle`.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from linkevo.sim.linkage import kernels, reference

FOOT_TRIANGLES = [  # (angle from A, angle from C) in degrees, and whether the foot is up
    ((350.0, 10.0), False),  # mean 180: not up ((-pi, pi] would say 0, also not up)
    ((200.0, 80.0), True),  # mean 140: up ((-pi, pi] would say -40, not up)
    ((345.5, 10.0), True),  # mean 177.75: up ((-pi, pi] would say -2.25, not up)
    ((350.5, 10.0), False),  # mean 180.25: not up ((-pi, pi] would say 0.25, up)
    ((30.0, 150.0), True),  # both up
    ((200.0, 300.0), False),  # both down
    ((190.0, 0.0), True),  # mean 95: up ((-pi, pi] would say -85, not up); dy = 0 at C
]


def _anchor(foot: tuple[float, float], degrees: float, length: float) -> tuple[float, float]:
    """Returns the anchor from which a beam of `length` reaches `foot` at `degrees`."""
    a = math.radians(degrees)
    return (foot[0] - length * math.cos(a), foot[1] - length * math.sin(a))


def _triangle_foot_tables(cases):
    """Returns ni (12, 4), bi (15, 6), xs, ys (12, A) for a triangle foot (node 7) held by
    nodes 5 and 6, one case per sample."""
    n = len(cases)
    ni = np.zeros((12, 4), dtype=np.int64)
    ni[7] = [kernels.TRIANGLE, 5, 6, 0]
    bi = np.full((15, 6), -1, dtype=np.int64)
    bi[0] = [0, kernels.CRANK_TIP, kernels.B_CRANK, -1, 0, 0]
    bi[1] = [5, 7, kernels.B_TRIANGLE, -1, 1, 0]
    bi[2] = [6, 7, kernels.B_TRIANGLE, -1, 2, 0]
    xs = np.zeros((12, n))
    ys = np.zeros((12, n))
    for k, ((from_a, from_c), _) in enumerate(cases):
        xs[5, k], ys[5, k] = _anchor((0.0, 0.0), from_a, 3.0)
        xs[6, k], ys[6, k] = _anchor((0.0, 0.0), from_c, 4.0)
    return ni, bi, xs, ys


def test_reference_beam_angles_lie_in_zero_to_two_pi():
    for degrees in (0.0, 10.0, 179.0, 180.0, 181.0, 270.0, 350.0):
        start = _anchor((0.0, 0.0), degrees, 2.0)
        angle = reference.beam_angle(start, (0.0, 0.0))
        assert 0.0 <= angle < 2.0 * math.pi
        assert math.isclose(angle, math.radians(degrees), abs_tol=1e-12)


@pytest.mark.parametrize("legacy", [False, True])
def test_triangle_foot_is_up_where_the_mean_recorded_angle_lies_in_zero_to_pi(legacy):
    ni, bi, xs, ys = _triangle_foot_tables(FOOT_TRIANGLES)
    n = len(FOOT_TRIANGLES)
    valid = np.ones(n, dtype=np.bool_)
    codes = np.zeros(n, dtype=np.int64)
    theta = np.zeros(n)
    by_rule = []
    for k in range(n):
        foot = (xs[7, k], ys[7, k])
        mean = (
            reference.beam_angle((xs[5, k], ys[5, k]), foot)
            + reference.beam_angle((xs[6, k], ys[6, k]), foot)
        ) / 2
        by_rule.append(0.0 < mean < math.pi)
    assert by_rule == [up for _, up in FOOT_TRIANGLES]
    f_ae = kernels.angle_error(7, ni, bi, 3, xs, ys, valid, theta, legacy, codes)
    if not legacy:
        assert f_ae == sum(by_rule)
    for k in range(n):  # one sample at a time: the kernel's per-sample answer
        one = np.zeros(n, dtype=np.bool_)
        one[k] = True
        count = kernels.angle_error(7, ni, bi, 3, xs, ys, one, theta, False, codes)
        assert count == float(by_rule[k]), FOOT_TRIANGLES[k]


@pytest.mark.parametrize(
    ("root_degrees", "inversions", "up"),
    [(80.0, 0, True), (80.0, 1, False), (200.0, 0, False), (200.0, 1, False), (350.0, 2, False)],
)
def test_extension_foot_angle_is_its_root_plus_pi_per_inversion(root_degrees, inversions, up):
    # (-pi, pi] would record 200 degrees as -160, and -160 + 180 = 20 would point up.
    ni = np.zeros((12, 4), dtype=np.int64)
    ni[6] = [kernels.TRIANGLE, 5, 5, 0]
    ni[7] = [kernels.EXTENSION, 1, inversions % 2, 0]
    bi = np.full((15, 6), -1, dtype=np.int64)
    bi[0] = [0, kernels.CRANK_TIP, kernels.B_CRANK, -1, 0, 0]
    bi[1] = [5, 6, kernels.B_TRIANGLE, -1, 1, 0]
    bi[2] = [6, 7, kernels.B_EXTENSION, 1, 1, inversions]
    xs = np.zeros((12, 1))
    ys = np.zeros((12, 1))
    xs[5, 0], ys[5, 0] = _anchor((0.0, 0.0), root_degrees, 3.0)
    valid = np.ones(1, dtype=np.bool_)
    codes = np.zeros(1, dtype=np.int64)
    count = kernels.angle_error(7, ni, bi, 3, xs, ys, valid, np.zeros(1), False, codes)
    recorded = reference.beam_angle((xs[5, 0], ys[5, 0]), (0.0, 0.0)) + inversions * math.pi
    assert (0.0 < recorded < math.pi) == up
    assert count == float(up)
