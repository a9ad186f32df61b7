"""Provides the kernels' geometry: circle intersections (spec §2), unit directions, the
beam and dependency tables a decode fills, crank angles.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from linkevo.sim.linkage.kernels.codes import MAX_ANCHOR_DIST, MIN_ANCHOR_DIST, TOL
from linkevo.sim.linkage.kernels.jit import _BATCH, _INLINE, _JIT


@numba.njit(**_INLINE)
def distance_terms(dx, dy, r_sum, r_diff, k2):
    """Returns (d, good, inv, along) of anchors (dx, dy) apart, for circles of radii r0, r1
    (r_sum = r0 + r1, r_diff = |r0 - r1|, k2 = r0 * r0 - r1 * r1): their distance d,
    whether the circles meet (within the tolerance), 1/d' for d' = d moved into the
    tolerance band, and the distance a from P0 along the anchors' line (spec §2)."""
    d = math.sqrt(dx * dx + dy * dy)
    good = (d - TOL <= r_sum) & (d + TOL >= r_diff)
    dn = d - TOL if d > r_sum else (d + TOL if d < r_diff else d)
    inv = 1.0 / dn  # one division per triangle (docs/simulator.md, floating-point forms)
    return d, good, inv, 0.5 * (k2 + dn * dn) * inv


@numba.njit(**_INLINE)
def circle_point(p0x, p0y, p1x, p1y, r0, r1, side):
    """Returns (x, y, good, d, ex, ey): spec §2 circle_intersection of anchors P0, P1 in
    the generic case (see triangle_point), written as selects.

    side is +1.0 (direction 0) or -1.0. good is False where there is no solution (x, y
    are then meaningless); d is the anchors' distance and (ex, ey) the unit vector from P0
    towards P1 (over the distance moved into the tolerance band).
    """
    dx = p1x - p0x
    dy = p1y - p0y
    d, good, inv, along = distance_terms(dx, dy, r0 + r1, abs(r0 - r1), r0 * r0 - r1 * r1)
    ex = dx * inv
    ey = dy * inv
    h = side * math.sqrt(max(r0 * r0 - along * along, 0.0))
    return p0x + along * ex + h * ey, p0y + along * ey - h * ex, good, d, ex, ey


@numba.njit(**_INLINE)
def triangle_point(p0x, p0y, p1x, p1y, r0, r1, side, back_x, back_y, legacy):
    """Returns (x, y, good): spec §2 circle_intersection of anchors P0, P1, written as selects.

    Adds to circle_point the legacy tangent case and coincident anchors with r0 == r1,
    which take the backup point; back_x/back_y is its offset (see decode_and_simulate).
    """
    x, y, good, d, ex, ey = circle_point(p0x, p0y, p1x, p1y, r0, r1, side)
    if legacy:
        tangent = abs(d - r0 + r1) < TOL
        x = p0x + r0 * ex if tangent else x
        y = p0y + r0 * ey if tangent else y
    coincident = (d == 0.0) & (r0 == r1)
    x = (back_x if legacy else p0x + back_x) if coincident else x
    y = (back_y if legacy else p0y + back_y) if coincident else y
    return x, y, good


@numba.njit(**_INLINE)
def unit_direction(dx, dy):
    """Returns the unit vector along (dx, dy); (1, 0) when it is zero (atan2(0, 0) = 0)."""
    norm = math.sqrt(dx * dx + dy * dy)
    zero = norm == 0.0
    inv = 1.0 / norm
    return 1.0 if zero else dx * inv, 0.0 if zero else dy * inv


@numba.njit(**_INLINE)
def set_beam(bi, bf, b, start, end, kind, parent, length):
    """Records beam b; its root is itself and it has no inversions unless told later."""
    bi[b, 0] = start
    bi[b, 1] = end
    bi[b, 2] = kind
    bi[b, 3] = parent
    bi[b, 4] = b
    bi[b, 5] = 0
    bf[b] = length


@numba.njit(**_INLINE)
def add_to_graph(j, p, q, depth, ancestors):
    """Records node j with parents p, q in the decode graph: depth and ancestors (12,)."""
    depth[j] = 1 + max(depth[p], depth[q])
    ancestors[j] = (1 << j) | ancestors[p] | ancestors[q]


@numba.njit(**_JIT)
def repair_anchor(a, c, n_nodes, xs, ys):
    """Returns anchor C after the published repair loop (spec §2, docs/simulator.md);
    column 0 of xs/ys (12, A) holds the nodes' positions at angle 0."""
    first = c
    check_min = True
    while True:
        d = math.sqrt((xs[a, 0] - xs[c, 0]) ** 2 + (ys[a, 0] - ys[c, 0]) ** 2)
        if not (a == c or d > MAX_ANCHOR_DIST or (check_min and d < MIN_ANCHOR_DIST)):
            return c
        c -= 1
        if c == 0:
            c = n_nodes - 1
        if c == first:
            if not check_min:
                return first
            check_min = False


@numba.njit(**_BATCH)
def crank_angles(n_angles, legacy):
    """Returns the A crank angles (legacy accumulates 2*pi/A; paper uses k*2*pi/A)."""
    theta = np.empty(n_angles)
    theta[0] = 0.0
    for k in range(1, n_angles):
        if legacy:
            theta[k] = theta[k - 1] + 2.0 * math.pi / n_angles
        else:
            theta[k] = k * 2.0 * math.pi / n_angles
    return theta


@numba.njit(**_JIT)
def fill_row(j, x, y, xs, ys):
    """Writes the position (x, y) of a node that does not move to row j of xs/ys (12, A),
    every column."""
    for k in range(xs.shape[1]):
        xs[j, k] = x
    for k in range(xs.shape[1]):
        ys[j, k] = y
