"""Provides the numba kernels: decode, per-angle kinematics, foot, fitness and descriptors.

Everything here works on one linkage at a time inside `prange` loops over chunks of the
batch; the numpy-facing wrappers live in `decode.py`, `kinematics.py` and `evaluate.py`.
Per-linkage topology is packed into small arrays (see `decode.py` for their layout).
Positions are (12, A) arrays, one column per crank angle: the topology is shared by every
column, so the loops over columns carry no data-dependent branches and vectorise. The hot
loops index whole arrays rather than slicing them (a slice builds a view on every use).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from linkevo.sim.genome import BLOCK_SIZE, CRANK_GENE, FIRST_BLOCK, MAX_BEAMS, N_NODES

TOL = 0.1
"""The tolerance of circle_intersection (spec §2), as published."""
L_MAX = 15.0
L_MIN = 2.0
MAX_ANCHOR_DIST = 30.0
MIN_ANCHOR_DIST = 0.1
BAND = 0.5
"""F_sl contact band above the lowest sample."""
NAN_OR_ONE = np.array([np.nan, 1.0])
"""A failed (0) sample's foot position times NaN is NaN, a recorded (1) one's times 1 is
itself, bit for bit (foot_path)."""

# Node kinds (column 0 of the node table) and beam kinds.
MOTOR, STATIC, CRANK, TRIANGLE, EXTENSION = 0, 1, 2, 3, 4
B_CRANK, B_TRIANGLE, B_EXTENSION = 0, 1, 2
CRANK_TIP = 4

# Fitness codes.
FP, FSL, FP2, FSL2 = 0, 1, 2, 3


NOALIAS_ENV = "LINKEVO_NUMBA_NOALIAS"
"""Set to 0 to compile every kernel without `noalias` (same results, more slowly)."""


def enable_noalias() -> dict[str, bool]:
    """Registers numba's `noalias` flag as the jit option `_noalias`; returns the option
    to pass to `numba.njit`, or {} (the fallback) where this numba lacks the flag or
    LINKEVO_NUMBA_NOALIAS=0.

    The one change linkevo makes to numba, made once at import of this module: it adds
    the `_noalias` entry to numba's CPU target options (process-wide; a function compiled
    without the option is unaffected). numba has the flag (`Flags.noalias`, which its
    parfor lowering sets on the loop bodies it outlines) but maps no decorator option to
    it. With it, LLVM knows no two array arguments of a helper overlap and vectorises
    without run-time overlap checks: measured, 1.2-1.35x evaluations per second, and 1.3x
    per AURORA training step (`algorithms.aurora_kernel`), whose training is most of a
    MAP-AU trial (docs/simulator.md, "Kernel design"). The fallback compiles the same
    code without the flag: equal outputs (`tests/sim/test_noalias_fallback.py`).
    """
    import os

    from numba.core import compiler, cpu, options

    if os.environ.get(NOALIAS_ENV, "1") == "0":
        return {}
    needed = (
        (compiler.Flags, "noalias"),
        (options.TargetOptions, "Mapping"),
        (cpu, "CPUTargetOptions"),
    )
    if not all(hasattr(owner, name) for owner, name in needed):
        return {}
    cpu.CPUTargetOptions._noalias = options.TargetOptions.Mapping("noalias")
    return {"_noalias": True}


NOALIAS = enable_noalias()
"""The jit option of every helper whose array arguments never overlap ({} in the fallback)."""

_BATCH = {"cache": True, "nogil": True, "error_model": "numpy"}
"""For the batch entry points, which allocate their scratch arrays."""
_JIT = {**_BATCH, "_nrt": False, "forceinline": True, **NOALIAS}
"""For the per-linkage helpers. They never allocate, so they are compiled without numba's
reference counting, which otherwise costs two calls per array argument per call. LLVM
inlines them into the batch loops, and their array arguments are `noalias`: no two of them
may overlap in memory while the helper runs (every caller passes distinct scratch and
output arrays; `sim.evaluating` refuses overlapping outputs). Knowing that, LLVM vectorises
their loops without run-time overlap checks, and inlined they pay no argument passing:
together a quarter of the evaluation's time (docs/simulator.md, "Kernel design")."""
_INLINE = {**_JIT, "inline": "always"}
"""For the small per-sample helpers called inside loops that must vectorise."""


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
        xs[a, 0], ys[a, 0], xs[c, 0], ys[c, 0], nf[new, 0], nf[new, 1], side,
        nf[new, 3], nf[new, 4], legacy,
    )  # fmt: skip
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


@numba.njit(**_JIT)
def recorded_angle(b, k, bi, xs, ys, theta):
    """Returns beam b's recorded angle at sample k (docs/simulator.md, "Beam angle").

    The crank's is theta[k]; a triangle beam's is atan2 of its end minus its start, moved
    into [0, 2 pi) by adding 2 pi where negative (spec §2, the published code's addition);
    an extension's is its root beam's plus pi for each inverted link, added one at a time.
    """
    root = bi[b, 4]
    if bi[root, 2] == B_CRANK:
        angle = theta[k]
    else:
        s = bi[root, 0]
        e = bi[root, 1]
        angle = math.atan2(ys[e, k] - ys[s, k], xs[e, k] - xs[s, k])
        if angle < 0.0:
            angle += 2.0 * math.pi
    for _ in range(bi[b, 5]):
        angle += math.pi
    return angle


@numba.njit(**_INLINE)
def triangle_up(dxa, dya, dxc, dyc):
    """Returns 1 or 0 when signs alone settle whether a triangle foot points up, else -1.

    (dxa, dya) and (dxc, dyc) are the foot minus anchors A and C. The recorded angles lie
    in [0, 2 pi), and their mean lies in (0, pi) exactly when their sum lies in (0, 2 pi).
    Both down: both angles exceed pi. Both clearly up: both lie strictly inside (0, pi) (a
    margin keeps clear of atan2 rounding to pi). One up (u in (0, pi)), one down (2 pi + v,
    v in (-pi, 0)): the sum is below 2 pi exactly when u + v < 0, whose sign is that of
    sin(u + v), a cross product; within rounding of zero the angles themselves must decide
    (two atan2 values can cancel exactly where the cross product is a few ulps off).
    Written as selects.
    """
    down = (dya < 0.0) & (dyc < 0.0)
    up = (dya > 1e-9 * abs(dxa)) & (dyc > 1e-9 * abs(dxc))
    mixed = ((dya > 0.0) & (dyc < 0.0)) | ((dya < 0.0) & (dyc > 0.0))
    cross = dxa * dyc + dxc * dya
    settled = mixed & (abs(cross) > 1e-9 * (abs(dxa * dyc) + abs(dxc * dya)))
    by_cross = (1 if cross < 0.0 else 0) if settled else -1
    return 0 if down else (1 if up else by_cross)


@numba.njit(**_JIT)
def up_by_sign(foot, ni, bi, b, xs, ys, theta, codes):
    """Fills codes (A,) with 1 or 0 where signs alone settle whether the foot points up at
    that sample, else -1 (see triangle_up); meaningless at failed samples.

    "Up" means the mean recorded angle of the beams ending at the foot lies in (0, pi);
    b is the one beam ending at a crank-tip or extension foot. Every settled case agrees
    with the angles themselves (`points_up`).
    """
    n = codes.shape[0]
    if ni[foot, 0] == TRIANGLE:
        a = ni[foot, 1]
        c = ni[foot, 2]
        for k in range(n):
            codes[k] = triangle_up(
                xs[foot, k] - xs[a, k],
                ys[foot, k] - ys[a, k],
                xs[foot, k] - xs[c, k],
                ys[foot, k] - ys[c, k],
            )
        return
    # One beam: its angle is its root's plus m times pi, the root's lying in [0, 2 pi)
    # (a triangle beam or the crank); with m >= 1 it is at least pi.
    root = bi[b, 4]
    if bi[b, 5] >= 1:
        codes[:] = 0
    elif bi[root, 2] == B_CRANK:
        for k in range(n):
            codes[k] = 1 if 0.0 < theta[k] < math.pi else 0
    else:
        s = bi[root, 0]
        e = bi[root, 1]
        for k in range(n):
            dx = xs[e, k] - xs[s, k]
            dy = ys[e, k] - ys[s, k]
            codes[k] = 1 if dy > 1e-9 * abs(dx) else (0 if dy <= 0.0 else -1)


@numba.njit(**_JIT)
def points_up(foot, k, bi, n_beams, xs, ys, theta):
    """Returns whether the mean recorded angle of the foot's beams lies in (0, pi)."""
    s = 0.0
    m = 0
    for b in range(n_beams):
        if bi[b, 1] == foot:
            s += recorded_angle(b, k, bi, xs, ys, theta)
            m += 1
    return m > 0 and 0.0 < s / m < math.pi


@numba.njit(**_JIT)
def angle_error(foot, ni, bi, n_beams, xs, ys, valid, theta, legacy, codes):
    """Returns F_ae for one simulated linkage (paper: count; legacy: distance-weighted).

    codes (A,) int64 is scratch (see up_by_sign).
    """
    if ni[foot, 0] in (MOTOR, STATIC):
        return 0.0
    n_angles = valid.shape[0]
    last = 0
    for b in range(n_beams):
        last = b if bi[b, 1] == foot else last
    up_by_sign(foot, ni, bi, last, xs, ys, theta, codes)
    if not legacy:  # a count: the settled samples without branches, then the rest
        count = 0
        unsettled = 0
        for k in range(n_angles):
            count += 1 if valid[k] & (codes[k] == 1) else 0
            unsettled += 1 if valid[k] & (codes[k] < 0) else 0
        if unsettled:
            for k in range(n_angles):
                if valid[k] and codes[k] < 0 and points_up(foot, k, bi, n_beams, xs, ys, theta):
                    count += 1
        return float(count)
    # legacy: each upward sample weighs its distance from the previous recorded one
    prev = -1
    for k in range(n_angles - 1, -1, -1):
        if valid[k]:
            prev = k
            break
    total = 0.0
    for k in range(n_angles):
        if not valid[k]:
            continue
        up = codes[k]
        if up < 0:
            up = points_up(foot, k, bi, n_beams, xs, ys, theta)
        if up:
            total += math.sqrt(
                (xs[foot, k] - xs[foot, prev]) ** 2 + (ys[foot, k] - ys[foot, prev]) ** 2
            )
        prev = k
    return total


@numba.njit(**_JIT)
def find_foot(ys, valid, lows, rows):
    """Returns the node with the lowest y over the valid samples (first on ties).

    ys (12, A); valid (A,); lows (A,) float and rows (A,) int64 are scratch. The motor's
    and static nodes' y never change, so column 0 stands for them. For the others, one
    vector loop over the angles takes each angle's lowest y and its row (the first on
    ties); the foot is then the first row reaching the lowest of those, if that is lower
    than every motor and static node.
    """
    n = valid.shape[0]
    for k in range(n):
        low = ys[CRANK_TIP, k]
        row = CRANK_TIP
        for j in range(CRANK_TIP + 1, N_NODES):  # unrolled by LLVM
            y = ys[j, k]
            lower = y < low
            low = y if lower else low
            row = j if lower else row
        lows[k] = low if valid[k] else np.inf
        rows[k] = row
    foot = 0
    best = np.inf
    any_valid = 0
    for k in range(n):
        any_valid |= valid[k]
    if any_valid:
        for j in range(CRANK_TIP):
            if ys[j, 0] < best:
                best = ys[j, 0]
                foot = j
    low0 = low1 = low2 = low3 = np.inf  # four lanes: the minimum's order does not matter
    k = 0
    while k + 4 <= n:
        low0 = lows[k] if lows[k] < low0 else low0
        low1 = lows[k + 1] if lows[k + 1] < low1 else low1
        low2 = lows[k + 2] if lows[k + 2] < low2 else low2
        low3 = lows[k + 3] if lows[k + 3] < low3 else low3
        k += 4
    for j in range(k, n):
        low0 = lows[j] if lows[j] < low0 else low0
    low0 = low1 if low1 < low0 else low0
    low2 = low3 if low3 < low2 else low2
    low = low2 if low2 < low0 else low0
    if low < best:
        foot = N_NODES
        for k in range(n):  # the first row reaching it: an integer minimum, which vectorises
            row = rows[k] if lows[k] == low else N_NODES
            foot = row if row < foot else foot
    return foot


@numba.njit(**_JIT)
def foot_path(xs, ys, f, ok, px, py, valid, foot_x, foot_y, i):
    """Writes ok (A,) int64 0/1 to valid[i], node f's samples to foot_x[i]/foot_y[i] (NaN
    where failed) and the recorded ones, in order, to px/py (A,); returns their count.

    Written without branches: every sample is stored at px/py[count], and the count
    moves on past the recorded ones only; the NaN comes from a product with NAN_OR_ONE
    (a select here compiled to branches, mispredicted where the validity changes). The
    count and the flag are unsigned: a signed index costs a wraparound select per use.
    """
    n = np.uint64(0)
    for k in range(ok.shape[0]):
        v = np.uint64(ok[k])
        x = xs[f, k]
        y = ys[f, k]
        valid[i, k] = v
        foot_x[i, k] = x * NAN_OR_ONE[v]
        foot_y[i, k] = y * NAN_OR_ONE[v]
        px[n] = x
        py[n] = y
        n += v
    return np.int64(n)


@numba.njit(**_JIT)
def path_extent(px, py, n):
    """Returns (centroid x, centroid y, x_min, x_max, y_min, y_max, lowest) of the first
    n >= 1 samples of px/py; lowest is the first sample at y_min, and the centroid sums run
    in sample order."""
    cx = 0.0
    cy = 0.0
    x_min = x_max = px[0]
    y_min = y_max = py[0]
    lowest = 0
    for k in range(n):
        x = px[k]
        y = py[k]
        cx += x
        cy += y
        x_min = x if x < x_min else x_min
        x_max = x if x > x_max else x_max
        lowest = k if y < y_min else lowest
        y_min = y if y < y_min else y_min
        y_max = y if y > y_max else y_max
    return cx / n, cy / n, x_min, x_max, y_min, y_max, lowest


@numba.njit(**_INLINE)
def squared_distance(ax, ay, bx, by):
    """Returns the squared distance of points (ax, ay) and (bx, by)."""
    ex = ax - bx
    ey = ay - by
    return ex * ex + ey * ey


@numba.njit(**_JIT)
def nearest_distance(px, py, n, cx, cy, tx, ty, best, low_a, low_b):
    """Fills best (P,) with each target's distance to its nearest sample.

    Samples px/py (first n used, finite) are taken relative to their centroid (cx, cy);
    targets are tx/ty (P,); low_a/low_b (P,) are scratch for the running minima of the
    squared distances. The inner loops run over targets so that they vectorise. Each pass
    over the targets takes four samples (the last few go one by one), reads the running
    minima from one of low_a/low_b and writes them to the other: updating one array in
    place compiles to slow masked stores. A minimum does not depend on the order it is
    taken in, so the distances are the same bits as one sample at a time.
    """
    src = low_a
    dst = low_b
    src[:] = np.inf
    i = 0
    while i + 4 <= n:
        q0x, q0y = px[i] - cx, py[i] - cy
        q1x, q1y = px[i + 1] - cx, py[i + 1] - cy
        q2x, q2y = px[i + 2] - cx, py[i + 2] - cy
        q3x, q3y = px[i + 3] - cx, py[i + 3] - cy
        for t in range(tx.shape[0]):
            d0 = squared_distance(tx[t], ty[t], q0x, q0y)
            d1 = squared_distance(tx[t], ty[t], q1x, q1y)
            d2 = squared_distance(tx[t], ty[t], q2x, q2y)
            d3 = squared_distance(tx[t], ty[t], q3x, q3y)
            d0 = d1 if d1 < d0 else d0
            d2 = d3 if d3 < d2 else d2
            d0 = d2 if d2 < d0 else d0
            low = src[t]
            dst[t] = d0 if d0 < low else low
        src, dst = dst, src
        i += 4
    for j in range(i, n):
        qx = px[j] - cx
        qy = py[j] - cy
        for t in range(tx.shape[0]):
            d0 = squared_distance(tx[t], ty[t], qx, qy)
            low = src[t]
            dst[t] = d0 if d0 < low else low
        src, dst = dst, src
    for t in range(tx.shape[0]):  # best is neither scratch array, so this vectorises
        best[t] = math.sqrt(src[t])


@numba.njit(**_JIT)
def summed_distance(best, use):
    """Returns the sum of best[t] over the targets t with use[t], in target order."""
    total = 0.0
    for t in range(best.shape[0]):
        total += best[t] if use[t] else 0.0
    return total


@numba.njit(**_JIT)
def step_and_lift(px, py, n, y_min, low):
    """Returns (F_s, F_l) of a compacted path of n samples whose lowest y is y_min, first
    reached at sample low (docs/simulator.md); the loop is written with selects."""
    if n < 2:
        return 0.0, 0.0
    dx_low = px[low + 1 if low + 1 < n else 0] - px[low]
    stance = -1.0 if dx_low < 0.0 else 1.0
    f_s = 0.0
    f_l = 0.0
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        dx = px[j] - px[i]
        along = dx * stance  # > 0 moving with the stance, < 0 against it
        in_band = (py[i] - y_min <= BAND) & (py[j] - y_min <= BAND)
        f_s += abs(dx) if (along > 0.0) & in_band else 0.0
        rise = py[i] - y_min if along < 0.0 else 0.0
        f_l = rise if rise > f_l else f_l
    return f_s, f_l


@numba.njit(**_INLINE)
def mean_beam_length(bf, n_beams):
    """Returns m = mean((len - 2) * 10/13) over the beams (bf (15,))."""
    m = 0.0
    for b in range(n_beams):
        m += (bf[b] - 2.0) * 10.0 / 13.0
    return m / n_beams


@numba.njit(**_JIT)
def structure(bf, n_beams, foot, depth, ancestors, st, i):
    """Writes the MAP-ST values (m, depth, drive size, moving share) to st[i] (N, 4).

    depth and ancestors (12,) int64 are the decode graph's, from decode_and_simulate; a
    node moves when the crank tip is among its ancestors.
    """
    size = 0
    n_moving = 0
    chain = ancestors[foot]
    for j in range(N_NODES):
        member = (chain >> j) & 1
        size += member
        n_moving += member & (ancestors[j] >> CRANK_TIP)
    st[i, 0] = mean_beam_length(bf, n_beams)
    st[i, 1] = depth[foot] * 10.0 / 9.0
    st[i, 2] = size * 10.0 / 13.0
    st[i, 3] = n_moving * 10.0 / size


@numba.njit(parallel=True, **_BATCH)
def evaluate_batch(
    genomes, legacy, n_angles, fitness, targets, is_step, n_chunks,
    loss, error, angle_err, valid, foot, foot_x, foot_y, wh, lis, st,
):  # fmt: skip
    """Decodes, simulates and scores every genome; writes into the output arrays.

    genomes (N, 56); targets (P, 2); is_step (P,) bool; loss (N, 1) or (N, 2); error,
    foot (N,) int; angle_err (N,); valid (N, A); foot_x, foot_y (N, A); wh, lis (N, 2);
    st (N, 4). The batch is split into n_chunks contiguous chunks that share scratch.
    """
    n = genomes.shape[0]
    theta = crank_angles(n_angles, legacy)
    cos_t = np.cos(theta)
    sin_t = np.sin(theta)
    tx = targets[:, 0].copy()
    ty = targets[:, 1].copy()
    is_lift = ~is_step
    every = np.ones(targets.shape[0], np.bool_)
    for chunk in numba.prange(n_chunks):
        ni = np.empty((N_NODES, 4), np.int64)
        nf = np.empty((N_NODES, 5))
        bi = np.empty((MAX_BEAMS, 6), np.int64)
        bf = np.empty(MAX_BEAMS)
        xs = np.empty((N_NODES, n_angles))
        ys = np.empty((N_NODES, n_angles))
        ux = np.empty((MAX_BEAMS, n_angles))
        uy = np.empty((MAX_BEAMS, n_angles))
        depth = np.empty(N_NODES, np.int64)
        ancestors = np.empty(N_NODES, np.int64)
        ok = np.empty(n_angles, np.int64)  # 0/1: int64 lanes need no packing to bytes
        codes = np.empty(n_angles, np.int64)
        lows = np.empty(n_angles)
        rows = np.empty(n_angles, np.int64)
        px = np.empty(n_angles)
        py = np.empty(n_angles)
        best = np.empty(targets.shape[0])
        low_a = np.empty(targets.shape[0])
        low_b = np.empty(targets.shape[0])
        place_motor(cos_t, sin_t, xs, ys, ux, uy)
        for i in range(chunk * n // n_chunks, (chunk + 1) * n // n_chunks):
            n_beams = decode_and_simulate(
                genomes[i], legacy, cos_t, sin_t, ni, nf, bi, bf, xs, ys, ux, uy, ok,
                depth, ancestors,
            )  # fmt: skip
            f = find_foot(ys, ok, lows, rows)
            ae = angle_error(f, ni, bi, n_beams, xs, ys, ok, theta, legacy, codes)
            foot[i] = f
            angle_err[i] = ae
            m = foot_path(xs, ys, f, ok, px, py, valid, foot_x, foot_y, i)
            err = n_angles - m  # the failed angles
            error[i] = err
            cx, cy, x_min, x_max, y_min, y_max, low = path_extent(px, py, m)
            f_s, f_l = step_and_lift(px, py, m, y_min, low)
            penalty = err + ae
            if fitness in (FP, FP2):
                nearest_distance(px, py, m, cx, cy, tx, ty, best, low_a, low_b)
            if fitness == FP:
                loss[i, 0] = summed_distance(best, every) + penalty
            elif fitness == FP2:
                loss[i, 0] = summed_distance(best, is_step) + penalty
                loss[i, 1] = summed_distance(best, is_lift) + penalty
            elif fitness == FSL:
                loss[i, 0] = -0.8 * f_s - 0.2 * f_l + penalty
            else:
                loss[i, 0] = -f_s + penalty
                loss[i, 1] = -f_l + penalty
            wh[i, 0] = y_max - y_min
            wh[i, 1] = x_max - x_min
            structure(bf, n_beams, f, depth, ancestors, st, i)
            lis[i, 0] = st[i, 0]
            lis[i, 1] = f_l


@numba.njit(parallel=True, **_BATCH)
def decode_batch(genomes, legacy, ni, nf, bi, bf, n_beams, pos0):
    """Decodes every genome at angle 0 into the packed topology arrays (see decode.py):
    the decoding simulated at the one crank angle 0."""
    cos_t = np.ones(1)
    sin_t = np.zeros(1)
    for i in numba.prange(genomes.shape[0]):
        xs = np.empty((N_NODES, 1))
        ys = np.empty((N_NODES, 1))
        ux = np.empty((MAX_BEAMS, 1))
        uy = np.empty((MAX_BEAMS, 1))
        ok = np.empty(1, np.bool_)
        depth = np.empty(N_NODES, np.int64)
        ancestors = np.empty(N_NODES, np.int64)
        place_motor(cos_t, sin_t, xs, ys, ux, uy)
        n_beams[i] = decode_and_simulate(
            genomes[i], legacy, cos_t, sin_t, ni[i], nf[i], bi[i], bf[i], xs, ys, ux, uy, ok,
            depth, ancestors,
        )  # fmt: skip
        pos0[i, :, 0] = xs[:, 0]
        pos0[i, :, 1] = ys[:, 0]


@numba.njit(parallel=True, **_BATCH)
def simulate_batch(ni, nf, bi, n_beams, n_angles, legacy, positions, valid, bang, foot):
    """Simulates decoded linkages: positions (N, 12, A, 2), valid (N, A), bang (N, 15, A).

    Positions at failed angles are NaN.
    """
    theta = crank_angles(n_angles, legacy)
    cos_t = np.cos(theta)
    sin_t = np.sin(theta)
    for i in numba.prange(ni.shape[0]):
        xs = np.empty((N_NODES, n_angles))
        ys = np.empty((N_NODES, n_angles))
        ux = np.empty((MAX_BEAMS, n_angles))
        uy = np.empty((MAX_BEAMS, n_angles))
        place_motor(cos_t, sin_t, xs, ys, ux, uy)
        simulate_one(ni[i], nf[i], bi[i], cos_t, sin_t, legacy, xs, ys, ux, uy, valid[i])
        foot[i] = find_foot(ys, valid[i], np.empty(n_angles), np.empty(n_angles, np.int64))
        for k in range(n_angles):
            if valid[i, k]:
                for b in range(n_beams[i]):
                    bang[i, b, k] = recorded_angle(b, k, bi[i], xs, ys, theta)
            else:
                xs[:, k] = np.nan
                ys[:, k] = np.nan
        positions[i, :, :, 0] = xs
        positions[i, :, :, 1] = ys
