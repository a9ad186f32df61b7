"""Provides the kernels that decode one linkage and place its nodes at every crank angle
(spec §3-§4): the motor, statics, crank, extensions and triangles.

The kernels' argument lists of 15-30 arrays are laid out by hand (ruff told to skip them): one
argument per line, as ruff would lay them out, spreads each call over a screen.
"""

from __future__ import annotations

import math

import numba

from linkevo.sim.linkage.genome import BLOCK_SIZE, CRANK_GENE, FIRST_BLOCK, N_NODES
from linkevo.sim.linkage.kernels.codes import (
    B_CRANK,
    B_EXTENSION,
    B_TRIANGLE,
    CRANK,
    CRANK_TIP,
    EXTENSION,
    L_MAX,
    L_MIN,
    MOTOR,
    STATIC,
    TOL,
    TRIANGLE,
)
from linkevo.sim.linkage.kernels.geometry import (
    add_to_graph,
    distance_terms,
    fill_row,
    repair_anchor,
    set_beam,
    triangle_point,
    unit_direction,
)
from linkevo.sim.linkage.kernels.jit import _JIT


@numba.njit(**_JIT)
def place_motor(cos_t, sin_t, xs, ys, ux, uy):
    """Places the motor (row 0 of xs/ys (12, A)) and the crank's direction (row 0 of
    ux/uy (15, A)): the same for every linkage, so written once per scratch array."""
    fill_row(0, 0.0, 0.0, xs, ys)
    for k in range(xs.shape[1]):
        ux[0, k] = cos_t[k]
    for k in range(xs.shape[1]):
        uy[0, k] = sin_t[k]


@numba.njit(**_JIT)
def place_base(nf, cos_t, sin_t, xs, ys):
    """Places the static nodes and crank tip in every column (crank angle) of xs/ys
    (12, A). Each loop writes one row: a loop writing several rows of arrays that might
    overlap does not vectorise."""
    n = xs.shape[1]
    for s in range(1, 4):
        fill_row(s, nf[s, 0], nf[s, 1], xs, ys)
    crank = nf[CRANK_TIP, 0]
    for k in range(n):
        xs[CRANK_TIP, k] = crank * cos_t[k]
    for k in range(n):
        ys[CRANK_TIP, k] = crank * sin_t[k]


@numba.njit(**_JIT)
def place_extension(new, b, ni, nf, bi, xs, ys, ux, uy, n):
    """Places extension node `new` (its beam is b) in the first n columns of xs/ys (12, A).

    ux/uy (15, A) hold the directions of the crank and extension beams
    (docs/simulator.md); b's is written. A triangle parent's direction is computed from
    the current positions.
    """
    parent = ni[new, 1]
    sign = -1.0 if ni[new, 2] else 1.0
    start = bi[b, 0]
    length = nf[new, 0]
    if bi[parent, 2] == B_TRIANGLE:
        s = bi[parent, 0]
        e = bi[parent, 1]
        for k in range(n):
            dx, dy = unit_direction(xs[e, k] - xs[s, k], ys[e, k] - ys[s, k])
            dx = sign * dx
            dy = sign * dy
            xs[new, k] = xs[start, k] + length * dx
            ys[new, k] = ys[start, k] + length * dy
            ux[b, k] = dx
            uy[b, k] = dy
        return
    for k in range(n):
        dx = sign * ux[parent, k]
        dy = sign * uy[parent, k]
        xs[new, k] = xs[start, k] + length * dx
        ys[new, k] = ys[start, k] + length * dy
        ux[b, k] = dx
        uy[b, k] = dy


@numba.njit(**_JIT)
def place_triangle(new, ni, nf, legacy, xs, ys, ok):
    """Places triangle node `new` in every column of xs/ys (12, A); clears ok (A,) where
    it has no solution (positions there are left meaningless).

    Anchors can coincide with the backup point taken only when r0 == r1: every other
    triangle runs the generic circle_point, split in two passes over the angles. The first
    stores 1/d' and a in the node's own rows, the second reads them back and places the
    node: each pass has a shorter dependency chain than one pass would, so more angles are
    in flight at once (docs/simulator.md, "Kernel design"). Legacy's tangent point
    P0 + r0 e is the generic formula with a = r0, whose h is then a zero, so the first
    pass stores r0 there: adding
    that zero changes no bit, as P0 + r0 e is never -0 (docs/simulator.md). Otherwise
    the first pass is circle_point's distance_terms and the second the rest of its
    operations, in its order, so the results are the same bit for bit.
    """
    a = ni[new, 1]
    c = ni[new, 2]
    r0 = nf[new, 0]
    r1 = nf[new, 1]
    side = 1.0 if ni[new, 3] == 0 else -1.0
    if r0 == r1:
        back_x = nf[new, 3]
        back_y = nf[new, 4]
        for k in range(xs.shape[1]):
            x, y, good = triangle_point(
                xs[a, k], ys[a, k], xs[c, k], ys[c, k], r0, r1, side, back_x, back_y, legacy
            )
            xs[new, k] = x
            ys[new, k] = y
            ok[k] = ok[k] & good
        return
    r_sum = r0 + r1
    r_diff = abs(r0 - r1)
    r0_sq = r0 * r0
    k2 = r0_sq - r1 * r1
    n = xs.shape[1]
    for k in range(n):
        d, good, inv, along = distance_terms(
            xs[c, k] - xs[a, k], ys[c, k] - ys[a, k], r_sum, r_diff, k2
        )
        ok[k] = ok[k] & good
        xs[new, k] = inv
        ys[new, k] = r0 if legacy & (abs(d - r0 + r1) < TOL) else along
    for k in range(n):
        p0x = xs[a, k]
        p0y = ys[a, k]
        inv = xs[new, k]
        along = ys[new, k]
        ex = (xs[c, k] - p0x) * inv
        ey = (ys[c, k] - p0y) * inv
        h = side * math.sqrt(max(r0_sq - along * along, 0.0))
        xs[new, k] = p0x + along * ex + h * ey
        ys[new, k] = p0y + along * ey - h * ex


@numba.njit(**_JIT)
def place_fixed_triangle(new, ni, nf, legacy, xs, ys, ok):
    """Places triangle node `new` whose anchors do not move: computed once, at column 0
    (triangle_point: the same operations as place_triangle's), and copied to every column
    of xs/ys (12, A); clears all of ok (A,) if it has no solution."""
    a = ni[new, 1]
    c = ni[new, 2]
    side = 1.0 if ni[new, 3] == 0 else -1.0
    x, y, good = triangle_point(
        xs[a, 0],
        ys[a, 0],
        xs[c, 0],
        ys[c, 0],
        nf[new, 0],
        nf[new, 1],
        side,
        nf[new, 3],
        nf[new, 4],
        legacy,
    )
    fill_row(new, x, y, xs, ys)
    if not good:
        ok[:] = False


@numba.njit(**_JIT)
def decode_and_simulate(
    g, legacy, cos_t, sin_t, ni, nf, bi, bf, xs, ys, ux, uy, ok, depth, ancestors
):  # fmt: skip
    """Decodes one genome (56,) and simulates it over A crank angles; returns the number
    of beams.

    Each block's lengths depend on its anchors' positions at angle 0, so the nodes are
    decoded and placed at every angle one at a time: cos_t/sin_t (A,) start at angle 0,
    and column 0 of xs/ys (12, A) is the decoding's angle-0 frame (the same float
    operations as any other column). Fills ni (12, 4) int [kind, a, c, dir], nf (12, 5)
    float [p0 .. p4], bi (15, 6) int [start, end, kind, parent, root, inversions] and bf
    (15,) beam lengths; xs/ys receive the positions (meaningless at failed angles), ux/uy
    (15, A) are scratch, and row 0 of xs/ys and ux/uy must hold what place_motor writes.
    ok (A,) (bool, or int64 0/1) receives per-angle success. depth and ancestors (12,)
    int64 receive each node's place in the decode graph (docs/simulator.md, MAP-ST): its
    depth in beams and its ancestors, itself included, as a 12-bit mask.

    Triangle: a=A, c=C, dir, p0=l1, p1=l2, p2=backup angle, p3/p4=l1 times its cosine and
    sine (the backup point's offset; only when l1 == l2, else 0). Extension: a=parent beam,
    c=inverted, p0=length. Static: p0=x, p1=y. Crank tip: p0=crank length. An extension's
    root is the crank or triangle beam its chain of parents starts from, and inversions
    counts the inverted links on that chain (its angle is the root's plus that many pi).

    A node moves when the crank tip is among its ancestors. One that does not (about a
    third of them in random genomes) is placed once and copied to every column: the same
    operations on the same inputs, so the same bits.
    """
    ni[:] = -1
    nf[:] = 0.0
    bi[:] = -1
    bf[:] = 0.0
    for j in range(CRANK_TIP):  # the robot connections: the motor and static nodes
        depth[j] = 0
        ancestors[j] = 1 << j
    depth[CRANK_TIP] = 1
    ancestors[CRANK_TIP] = (1 << CRANK_TIP) | 1  # the crank hangs from the motor
    ni[0, 0] = MOTOR
    for s in range(3):
        ni[1 + s, 0] = STATIC
        nf[1 + s, 0] = float(int(g[2 * s] * 11) - 5)
        nf[1 + s, 1] = float(int(g[2 * s + 1] * 11) - 5)
    crank = 2.0 + 6.0 * g[CRANK_GENE]
    ni[CRANK_TIP, 0] = CRANK
    nf[CRANK_TIP, 0] = crank
    set_beam(bi, bf, 0, 0, CRANK_TIP, B_CRANK, -1, crank)
    place_base(nf, cos_t, sin_t, xs, ys)
    ok[:] = True
    n_beams = 1
    for new in range(CRANK_TIP + 1, N_NODES):
        o = FIRST_BLOCK + BLOCK_SIZE * (new - CRANK_TIP - 1)
        if int(g[o] * 4) == 0:
            parent = int(g[o + 1] * n_beams)
            inverted = int(g[o + 3] * 2)
            length = 12.0 * g[CRANK_GENE] + 3.0 if legacy else 2.0 + 13.0 * g[o + 6]
            ni[new, 0] = EXTENSION
            ni[new, 1] = parent
            ni[new, 2] = inverted
            nf[new, 0] = length
            start = bi[parent, 0] if inverted else bi[parent, 1]
            set_beam(bi, bf, n_beams, start, new, B_EXTENSION, parent, length)
            chained = bi[parent, 2] == B_EXTENSION
            bi[n_beams, 4] = bi[parent, 4] if chained else parent
            bi[n_beams, 5] = inverted + (bi[parent, 5] if chained else 0)
            add_to_graph(new, bi[parent, 0], bi[parent, 1], depth, ancestors)
            if (ancestors[new] >> CRANK_TIP) & 1:
                place_extension(new, n_beams, ni, nf, bi, xs, ys, ux, uy, xs.shape[1])
            else:  # its children read its direction in column 0 only
                place_extension(new, n_beams, ni, nf, bi, xs, ys, ux, uy, 1)
                fill_row(new, xs[new, 0], ys[new, 0], xs, ys)
            n_beams += 1
            continue
        a = int(g[o + 1] * (new - 1)) + 1
        c = int(g[o + 2] * (new - 1)) + 1
        c = repair_anchor(a, c, new, xs, ys)
        d = math.sqrt((xs[a, 0] - xs[c, 0]) ** 2 + (ys[a, 0] - ys[c, 0]) ** 2)
        s1 = max(d - L_MAX, L_MIN)
        l1 = (L_MAX - s1) * g[o + 5] + s1
        lo = abs(d - l1)
        hi = min(d + l1, L_MAX)
        l2 = (hi - lo) * g[o + 6] + lo
        ni[new, 0] = TRIANGLE
        ni[new, 1] = a
        ni[new, 2] = c
        ni[new, 3] = int(g[o + 3] * 2)
        nf[new, 0] = l1
        nf[new, 1] = l2
        nf[new, 2] = 2.0 * math.pi * g[o + 4]
        if l1 == l2:  # the backup point serves only coincident anchors with r0 == r1
            nf[new, 3] = l1 * math.cos(nf[new, 2])
            nf[new, 4] = l1 * math.sin(nf[new, 2])
        set_beam(bi, bf, n_beams, a, new, B_TRIANGLE, -1, l1)
        set_beam(bi, bf, n_beams + 1, c, new, B_TRIANGLE, -1, l2)
        add_to_graph(new, a, c, depth, ancestors)
        if (ancestors[new] >> CRANK_TIP) & 1:
            place_triangle(new, ni, nf, legacy, xs, ys, ok)
        else:
            place_fixed_triangle(new, ni, nf, legacy, xs, ys, ok)
        n_beams += 2
    return n_beams


@numba.njit(**_JIT)
def count_failed(ok):
    """Returns the number of failed entries (False or 0) of ok (A,): the error count."""
    error = 0
    for k in range(ok.shape[0]):
        error += 0 if ok[k] else 1
    return error


@numba.njit(**_JIT)
def simulate_one(ni, nf, bi, cos_t, sin_t, legacy, xs, ys, ux, uy, valid):
    """Simulates one decoded linkage over A crank angles; returns the error count.

    cos_t/sin_t (A,) are the crank angles' cosines and sines; xs/ys (12, A) receive the
    positions (meaningless at failed angles); ux/uy (15, A) are scratch, and row 0 of
    xs/ys and ux/uy must hold what place_motor writes; valid (A,) receives per-angle
    success.
    """
    place_base(nf, cos_t, sin_t, xs, ys)
    valid[:] = True
    b = 1
    for new in range(CRANK_TIP + 1, N_NODES):
        if ni[new, 0] == EXTENSION:
            place_extension(new, b, ni, nf, bi, xs, ys, ux, uy, xs.shape[1])
            b += 1
        else:
            place_triangle(new, ni, nf, legacy, xs, ys, valid)
            b += 2
    return count_failed(valid)
