"""Provides the numba kernels: decode, per-angle kinematics, foot, fitness and descriptors.

Everything here works on one linkage at a time inside `prange` loops over chunks of the
batch; the numpy-facing wrappers live in `decode.py`, `kinematics.py` and `evaluate.py`.
Per-linkage topology is packed into small arrays (see `decode.py` for their layout).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from sim.genome import BLOCK_SIZE, CRANK_GENE, FIRST_BLOCK, MAX_BEAMS, N_BLOCKS, N_NODES

TOL = 0.1
"""The tolerance of circle_intersection (spec §2), as published."""
L_MAX = 15.0
L_MIN = 2.0
MAX_ANCHOR_DIST = 30.0
MIN_ANCHOR_DIST = 0.1
BAND = 0.5
"""F_sl contact band above the lowest sample."""

# Node kinds (column 0 of the node table) and beam kinds.
MOTOR, STATIC, CRANK, TRIANGLE, EXTENSION = 0, 1, 2, 3, 4
B_CRANK, B_TRIANGLE, B_EXTENSION = 0, 1, 2

# Fitness codes.
FP, FSL, FP2, FSL2 = 0, 1, 2, 3

_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}
ANGLE_ZERO_COS = np.ones(1)
ANGLE_ZERO_SIN = np.zeros(1)


@numba.njit(**_JIT)
def place_base(nf, cos_t, sin_t, xs, ys, ux, uy):
    """Places the motor, static nodes and crank tip in every column (crank angle).

    xs/ys (12, A) receive positions; ux/uy (15, A) the crank's direction in row 0.
    """
    crank = nf[4, 0]
    for k in range(xs.shape[1]):
        xs[0, k] = 0.0
        ys[0, k] = 0.0
        for s in range(1, 4):
            xs[s, k] = nf[s, 0]
            ys[s, k] = nf[s, 1]
        xs[4, k] = crank * cos_t[k]
        ys[4, k] = crank * sin_t[k]
        ux[0, k] = cos_t[k]
        uy[0, k] = sin_t[k]


@numba.njit(**_JIT)
def place_node(new, b, ni, nf, bi, legacy, xs, ys, ux, uy, ok):
    """Places added node `new` (its first beam is b) in every column of xs/ys.

    One column per crank angle: the topology is shared, so the loops over columns carry
    no data-dependent branches and vectorise. ok (A,) is cleared where a triangle has no
    solution (spec §2 circle_intersection, steps 2 to 5, written as selects); positions
    there are left meaningless. ux/uy (15, A) hold beam directions (see docs/simulator.md).
    """
    n = xs.shape[1]
    if ni[new, 0] == EXTENSION:
        parent = ni[new, 1]
        if bi[parent, 2] == B_TRIANGLE:
            s = bi[parent, 0]
            e = bi[parent, 1]
            for k in range(n):
                dx = xs[e, k] - xs[s, k]
                dy = ys[e, k] - ys[s, k]
                norm = math.sqrt(dx * dx + dy * dy)
                zero = norm == 0.0
                ux[parent, k] = 1.0 if zero else dx / norm
                uy[parent, k] = 0.0 if zero else dy / norm
        sign = -1.0 if ni[new, 2] else 1.0
        start = bi[b, 0]
        length = nf[new, 0]
        for k in range(n):
            dx = sign * ux[parent, k]
            dy = sign * uy[parent, k]
            xs[new, k] = xs[start, k] + length * dx
            ys[new, k] = ys[start, k] + length * dy
            ux[b, k] = dx
            uy[b, k] = dy
        return
    a = ni[new, 1]
    c = ni[new, 2]
    r0 = nf[new, 0]
    r1 = nf[new, 1]
    side = 1.0 if ni[new, 3] == 0 else -1.0
    back_x = nf[new, 3]
    back_y = nf[new, 4]
    r_sum = r0 + r1
    r_diff = abs(r0 - r1)
    for k in range(n):
        p0x = xs[a, k]
        p0y = ys[a, k]
        dx = xs[c, k] - p0x
        dy = ys[c, k] - p0y
        d = math.sqrt(dx * dx + dy * dy)
        good = (d - TOL <= r_sum) & (d + TOL >= r_diff)
        dn = d - TOL if d > r_sum else (d + TOL if d < r_diff else d)
        ex = dx / dn
        ey = dy / dn
        along = (r0 * r0 - r1 * r1 + dn * dn) / (2.0 * dn)
        h = side * math.sqrt(max(r0 * r0 - along * along, 0.0))
        x = p0x + along * ex + h * ey
        y = p0y + along * ey - h * ex
        if legacy:
            tangent = abs(d - r0 + r1) < TOL
            x = p0x + r0 * ex if tangent else x
            y = p0y + r0 * ey if tangent else y
        coincident = (d == 0.0) & (r0 == r1)
        x = (back_x if legacy else p0x + back_x) if coincident else x
        y = (back_y if legacy else p0y + back_y) if coincident else y
        xs[new, k] = x
        ys[new, k] = y
        ok[k] = ok[k] & good


@numba.njit(**_JIT)
def decode_one(g, legacy, ni, nf, bi, bf, xs, ys, ux, uy, ok):
    """Decodes one genome (56,) at crank angle 0; returns the number of beams.

    Fills ni (12, 4) int [kind, a, c, dir], nf (12, 5) float [p0 .. p4], bi (15, 6) int
    [start, end, kind, parent, root, inversions], bf (15,) beam lengths, and the positions
    at angle 0 in column 0 of xs/ys (12, >=1); ux/uy (15, >=1) and ok (>=1,) are scratch.
    Triangle: a=A, c=C, dir, p0=l1, p1=l2, p2=backup angle, p3/p4=l1 times its cosine and
    sine (the backup point's offset; only when l1 == l2, else 0). Extension: a=parent beam,
    c=inverted, p0=length. Static: p0=x, p1=y. Crank tip: p0=crank length. An extension's
    root is the crank or triangle beam its chain of parents starts from, and inversions
    counts the inverted links on that chain (its angle is the root's plus that many pi).
    """
    ni[:] = -1
    nf[:] = 0.0
    bi[:] = -1
    bf[:] = 0.0
    ni[0, 0] = MOTOR
    for s in range(3):
        ni[1 + s, 0] = STATIC
        nf[1 + s, 0] = float(int(g[2 * s] * 11) - 5)
        nf[1 + s, 1] = float(int(g[2 * s + 1] * 11) - 5)
    crank = 2.0 + 6.0 * g[CRANK_GENE]
    ni[4, 0] = CRANK
    nf[4, 0] = crank
    set_beam(bi, bf, 0, 0, 4, B_CRANK, -1, crank)
    place_base(nf, ANGLE_ZERO_COS, ANGLE_ZERO_SIN, xs[:, :1], ys[:, :1], ux[:, :1], uy[:, :1])
    n_nodes = 5
    n_beams = 1
    for i in range(N_BLOCKS):
        o = FIRST_BLOCK + BLOCK_SIZE * i
        new = n_nodes
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
            n_added = 1
        else:
            a = int(g[o + 1] * (n_nodes - 1)) + 1
            c = int(g[o + 2] * (n_nodes - 1)) + 1
            c = repair_anchor(a, c, n_nodes, xs[:, 0], ys[:, 0])
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
            n_added = 2
        place_node(
            new, n_beams, ni, nf, bi, legacy, xs[:, :1], ys[:, :1], ux[:, :1], uy[:, :1], ok[:1]
        )
        n_beams += n_added
        n_nodes += 1
    return n_beams


@numba.njit(**_JIT)
def set_beam(bi, bf, b, start, end, kind, parent, length):
    """Records beam b; its root is itself and it has no inversions unless told later."""
    bi[b, 0] = start
    bi[b, 1] = end
    bi[b, 2] = kind
    bi[b, 3] = parent
    bi[b, 4] = b
    bi[b, 5] = 0
    bf[b] = length


@numba.njit(**_JIT)
def repair_anchor(a, c, n_nodes, px, py):
    """Returns anchor C after the published repair loop (spec §2, docs/simulator.md)."""
    first = c
    check_min = True
    while True:
        d = math.sqrt((px[a] - px[c]) ** 2 + (py[a] - py[c]) ** 2)
        if not (a == c or d > MAX_ANCHOR_DIST or (check_min and d < MIN_ANCHOR_DIST)):
            return c
        c -= 1
        if c == 0:
            c = n_nodes - 1
        if c == first:
            if not check_min:
                return first
            check_min = False


@numba.njit(**_JIT)
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
def simulate_one(ni, nf, bi, cos_t, sin_t, legacy, xs, ys, ux, uy, valid):
    """Simulates one decoded linkage over A crank angles; returns the error count.

    cos_t/sin_t (A,) are the crank angles' cosines and sines; xs/ys (12, A) receive the
    positions (NaN at failed angles); ux/uy (15, A) are scratch; valid (A,) receives
    per-angle success.
    """
    place_base(nf, cos_t, sin_t, xs, ys, ux, uy)
    valid[:] = True
    b = 1
    for new in range(5, N_NODES):
        place_node(new, b, ni, nf, bi, legacy, xs, ys, ux, uy, valid)
        b += 1 if ni[new, 0] == EXTENSION else 2
    error = 0
    for k in range(xs.shape[1]):
        if not valid[k]:
            error += 1
            for j in range(N_NODES):
                xs[j, k] = np.nan
                ys[j, k] = np.nan
    return error


@numba.njit(**_JIT)
def recorded_angle(b, k, bi, xs, ys, theta):
    """Returns beam b's recorded angle at sample k (docs/simulator.md, "Beam angle").

    The crank's is theta[k]; a triangle beam's is atan2 of its end minus its start; an
    extension's is its root beam's plus pi for each inverted link, added one at a time.
    """
    root = bi[b, 4]
    if bi[root, 2] == B_CRANK:
        angle = theta[k]
    else:
        s = bi[root, 0]
        e = bi[root, 1]
        angle = math.atan2(ys[e, k] - ys[s, k], xs[e, k] - xs[s, k])
    for _ in range(bi[b, 5]):
        angle += math.pi
    return angle


@numba.njit(**_JIT)
def up_by_sign(foot, k, ni, bi, b, xs, ys, theta):
    """Returns 1 or 0 when signs alone settle whether the foot points up at sample k, else -1.

    "Up" means the mean recorded angle of the beams ending at the foot lies in (0, pi);
    b is the one beam ending at a crank-tip or extension foot. Every settled case agrees
    with the angles themselves (`points_up`); a margin keeps clear of atan2 rounding to pi.
    """
    if ni[foot, 0] == TRIANGLE:
        # The mean of the two atan2 angles lies in (0, pi) exactly when their sum lies in
        # (0, 2 pi). Both down: both angles are negative. Both clearly up: both lie
        # strictly inside (0, pi). One up, one down: the sum is positive exactly when the
        # up beam turns further from +x than the mirrored down beam, a cross product.
        dxa = xs[foot, k] - xs[ni[foot, 1], k]
        dya = ys[foot, k] - ys[ni[foot, 1], k]
        dxc = xs[foot, k] - xs[ni[foot, 2], k]
        dyc = ys[foot, k] - ys[ni[foot, 2], k]
        if dya < 0.0 and dyc < 0.0:
            return 0
        if dya > 1e-9 * abs(dxa) and dyc > 1e-9 * abs(dxc):
            return 1
        if (dya > 0.0 and dyc < 0.0) or (dya < 0.0 and dyc > 0.0):
            # Within rounding of zero the angles themselves must decide: two atan2 values
            # can cancel exactly where the cross product is a few ulps off.
            cross = dxa * dyc + dxc * dya
            if abs(cross) > 1e-9 * (abs(dxa * dyc) + abs(dxc * dya)):
                return 1 if cross > 0.0 else 0
        return -1
    # One beam: its angle is its root's plus m times pi, the root's lying in [-pi, pi]
    # (a triangle beam) or [0, 2 pi) (the crank); with m >= 2 it is at least pi.
    root = bi[b, 4]
    m = bi[b, 5]
    if m >= 2:
        return 0
    if bi[root, 2] == B_CRANK:
        return 1 if m == 0 and 0.0 < theta[k] < math.pi else 0
    dx = xs[bi[root, 1], k] - xs[bi[root, 0], k]
    dy = ys[bi[root, 1], k] - ys[bi[root, 0], k]
    rise = dy if m == 0 else -dy
    if rise > 1e-9 * abs(dx):
        return 1
    return 0 if rise <= 0.0 else -1


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
def angle_error(foot, ni, bi, n_beams, xs, ys, valid, theta, legacy):
    """Returns F_ae for one simulated linkage (paper: count; legacy: distance-weighted)."""
    if ni[foot, 0] in (MOTOR, STATIC):
        return 0.0
    n_angles = valid.shape[0]
    last = 0
    for b in range(n_beams):
        if bi[b, 1] == foot:
            last = b
    prev = -1
    for k in range(n_angles - 1, -1, -1):
        if valid[k]:
            prev = k
            break
    total = 0.0
    for k in range(n_angles):
        if not valid[k]:
            continue
        up = up_by_sign(foot, k, ni, bi, last, xs, ys, theta)
        if up < 0:
            up = points_up(foot, k, bi, n_beams, xs, ys, theta)
        if up:
            if legacy:
                total += math.sqrt(
                    (xs[foot, k] - xs[foot, prev]) ** 2 + (ys[foot, k] - ys[foot, prev]) ** 2
                )
            else:
                total += 1.0
        prev = k
    return total


@numba.njit(**_JIT)
def find_foot(ys):
    """Returns the node with the lowest recorded y (first on ties; NaN samples never win)."""
    foot = 0
    best = np.inf
    for j in range(ys.shape[0]):
        low = np.inf
        for k in range(ys.shape[1]):
            low = ys[j, k] if ys[j, k] < low else low
        if low < best:
            best = low
            foot = j
    return foot


@numba.njit(**_JIT)
def compact_path(xs_foot, ys_foot, valid, px, py):
    """Copies the recorded foot samples into px/py; returns their count."""
    n = 0
    for k in range(valid.shape[0]):
        if valid[k]:
            px[n] = xs_foot[k]
            py[n] = ys_foot[k]
            n += 1
    return n


@numba.njit(**_JIT)
def nearest_squared(px, py, n, cx, cy, tx, ty, best):
    """Fills best (P,) with each target's squared distance to its nearest sample.

    Samples px/py (first n used) are taken relative to their centroid (cx, cy); targets
    are tx/ty (P,). The inner loop runs over targets so that it vectorises.
    """
    best[:] = np.inf
    for i in range(n):
        qx = px[i] - cx
        qy = py[i] - cy
        for t in range(tx.shape[0]):
            ex = tx[t] - qx
            ey = ty[t] - qy
            d2 = ex * ex + ey * ey
            best[t] = d2 if d2 < best[t] else best[t]


@numba.njit(**_JIT)
def summed_distance(best, use):
    """Returns the sum of sqrt(best[t]) over the targets t with use[t]."""
    total = 0.0
    for t in range(best.shape[0]):
        if use[t]:
            total += math.sqrt(best[t])
    return total


@numba.njit(**_JIT)
def step_and_lift(px, py, n):
    """Returns (F_s, F_l) of a compacted path of n samples (docs/simulator.md)."""
    if n < 2:
        return 0.0, 0.0
    low = 0
    for i in range(1, n):
        if py[i] < py[low]:
            low = i
    y_min = py[low]
    dx_low = px[low + 1 if low + 1 < n else 0] - px[low]
    stance = -1.0 if dx_low < 0.0 else 1.0
    f_s = 0.0
    f_l = 0.0
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        dx = px[j] - px[i]
        sign = 1.0 if dx > 0.0 else (-1.0 if dx < 0.0 else 0.0)
        if sign == stance and py[i] - y_min <= BAND and py[j] - y_min <= BAND:
            f_s += abs(dx)
        if sign == -stance and py[i] - y_min > f_l:
            f_l = py[i] - y_min
    return f_s, f_l


@numba.njit(**_JIT)
def structure(ni, bi, bf, n_beams, foot, graph, out):
    """Writes the MAP-ST values (m, depth, drive size, moving share) to out (4,).

    graph (12, 5) int64 is scratch: [parent 0, parent 1, depth, moving, in drive].
    """
    m = 0.0
    for b in range(n_beams):
        m += (bf[b] - 2.0) * 10.0 / 13.0
    m /= n_beams
    graph[:] = 0
    graph[:, :2] = -1
    parents = graph[:, :2]
    depth = graph[:, 2]
    moving = graph[:, 3]
    in_drive = graph[:, 4]
    parents[4, 0] = 0
    moving[4] = 1
    depth[4] = 1
    for j in range(5, N_NODES):
        if ni[j, 0] == EXTENSION:
            parents[j, 0] = bi[ni[j, 1], 0]
            parents[j, 1] = bi[ni[j, 1], 1]
        else:
            parents[j, 0] = ni[j, 1]
            parents[j, 1] = ni[j, 2]
        depth[j] = 1 + max(depth[parents[j, 0]], depth[parents[j, 1]])
        moving[j] = moving[parents[j, 0]] | moving[parents[j, 1]]
    in_drive[foot] = 1
    for j in range(N_NODES - 1, -1, -1):
        if in_drive[j]:
            for p in range(2):
                if parents[j, p] >= 0:
                    in_drive[parents[j, p]] = 1
    size = 0
    n_moving = 0
    for j in range(N_NODES):
        if in_drive[j]:
            size += 1
            if moving[j]:
                n_moving += 1
    out[0] = m
    out[1] = depth[foot] * 10.0 / 9.0
    out[2] = size * 10.0 / 13.0
    out[3] = n_moving * 10.0 / size


@numba.njit(parallel=True, **_JIT)
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
        graph = np.empty((N_NODES, 5), np.int64)
        px = np.empty(n_angles)
        py = np.empty(n_angles)
        best = np.empty(targets.shape[0])
        for i in range(chunk * n // n_chunks, (chunk + 1) * n // n_chunks):
            n_beams = decode_one(genomes[i], legacy, ni, nf, bi, bf, xs, ys, ux, uy, valid[i])
            err = simulate_one(ni, nf, bi, cos_t, sin_t, legacy, xs, ys, ux, uy, valid[i])
            f = find_foot(ys)
            ae = angle_error(f, ni, bi, n_beams, xs, ys, valid[i], theta, legacy)
            error[i] = err
            foot[i] = f
            angle_err[i] = ae
            foot_x[i] = xs[f]
            foot_y[i] = ys[f]
            m = compact_path(xs[f], ys[f], valid[i], px, py)
            cx = 0.0
            cy = 0.0
            for k in range(m):
                cx += px[k]
                cy += py[k]
            cx /= m
            cy /= m
            f_s, f_l = step_and_lift(px, py, m)
            penalty = err + ae
            if fitness in (FP, FP2):
                nearest_squared(px, py, m, cx, cy, tx, ty, best)
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
            wh[i, 0] = py[:m].max() - py[:m].min()
            wh[i, 1] = px[:m].max() - px[:m].min()
            structure(ni, bi, bf, n_beams, f, graph, st[i])
            lis[i, 0] = st[i, 0]
            lis[i, 1] = f_l


@numba.njit(parallel=True, **_JIT)
def decode_batch(genomes, legacy, ni, nf, bi, bf, n_beams, pos0):
    """Decodes every genome at angle 0 into the packed topology arrays (see decode.py)."""
    for i in numba.prange(genomes.shape[0]):
        xs = np.empty((N_NODES, 1))
        ys = np.empty((N_NODES, 1))
        ux = np.empty((MAX_BEAMS, 1))
        uy = np.empty((MAX_BEAMS, 1))
        ok = np.empty(1, np.bool_)
        n_beams[i] = decode_one(genomes[i], legacy, ni[i], nf[i], bi[i], bf[i], xs, ys, ux, uy, ok)
        pos0[i, :, 0] = xs[:, 0]
        pos0[i, :, 1] = ys[:, 0]


@numba.njit(parallel=True, **_JIT)
def simulate_batch(ni, nf, bi, n_beams, n_angles, legacy, positions, valid, bang, foot):
    """Simulates decoded linkages: positions (N, 12, A, 2), valid (N, A), bang (N, 15, A)."""
    theta = crank_angles(n_angles, legacy)
    cos_t = np.cos(theta)
    sin_t = np.sin(theta)
    for i in numba.prange(ni.shape[0]):
        xs = np.empty((N_NODES, n_angles))
        ys = np.empty((N_NODES, n_angles))
        ux = np.empty((MAX_BEAMS, n_angles))
        uy = np.empty((MAX_BEAMS, n_angles))
        simulate_one(ni[i], nf[i], bi[i], cos_t, sin_t, legacy, xs, ys, ux, uy, valid[i])
        foot[i] = find_foot(ys)
        for k in range(n_angles):
            if valid[i, k]:
                for b in range(n_beams[i]):
                    bang[i, b, k] = recorded_angle(b, k, bi[i], xs, ys, theta)
        positions[i, :, :, 0] = xs
        positions[i, :, :, 1] = ys
