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
"""circle_intersection's tolerance, as published."""
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


@numba.njit(**_JIT)
def circle_intersection(p0x, p0y, p1x, p1y, r0, r1, direction, backup, legacy):
    """Returns (ok, x, y): the point at r0 from P0 and r1 from P1 (spec §2)."""
    dx = p1x - p0x
    dy = p1y - p0y
    d = math.sqrt(dx * dx + dy * dy)
    if d - TOL > r0 + r1 or d + TOL < abs(r0 - r1):
        return False, 0.0, 0.0
    if d == 0.0 and r0 == r1:
        if legacy:
            return True, r0 * math.cos(backup), r0 * math.sin(backup)
        return True, p0x + r0 * math.cos(backup), p0y + r0 * math.sin(backup)
    if d > r0 + r1:
        dn = d - TOL
    elif d < abs(r0 - r1):
        dn = d + TOL
    else:
        dn = d
    ex = dx / dn
    ey = dy / dn
    if legacy and abs(d - r0 + r1) < TOL:
        return True, p0x + r0 * ex, p0y + r0 * ey
    a = (r0 * r0 - r1 * r1 + dn * dn) / (2.0 * dn)
    h = math.sqrt(max(r0 * r0 - a * a, 0.0))
    mx = p0x + a * ex
    my = p0y + a * ey
    if direction == 0:
        return True, mx + h * ey, my - h * ex
    return True, mx - h * ey, my + h * ex


@numba.njit(**_JIT)
def beam_unit(b, bi, px, py, ux, uy):
    """Returns beam b's unit direction (start -> end) at the current positions.

    Crank and extension directions are kept in ux/uy (15,); a triangle beam's comes from
    its end points ((1, 0) for a zero-length beam, as atan2(0, 0) = 0 would give).
    """
    if bi[b, 2] != B_TRIANGLE:
        return ux[b], uy[b]
    dx = px[bi[b, 1]] - px[bi[b, 0]]
    dy = py[bi[b, 1]] - py[bi[b, 0]]
    norm = math.sqrt(dx * dx + dy * dy)
    if norm == 0.0:
        return 1.0, 0.0
    return dx / norm, dy / norm


@numba.njit(**_JIT)
def place_extension(new, b, ni, nf, bi, px, py, ux, uy):
    """Places extension node `new` (its beam is b) along its parent beam's direction."""
    parent = ni[new, 1]
    dx, dy = beam_unit(parent, bi, px, py, ux, uy)
    if ni[new, 2]:
        dx = -dx
        dy = -dy
    start = bi[b, 0]
    length = nf[new, 0]
    px[new] = px[start] + length * dx
    py[new] = py[start] + length * dy
    ux[b] = dx
    uy[b] = dy


@numba.njit(**_JIT)
def decode_one(g, legacy, ni, nf, bi, bf, px, py, ux, uy):
    """Decodes one genome (56,) at crank angle 0; returns the number of beams.

    Fills ni (12, 4) int [kind, a, c, dir], nf (12, 3) float [p0, p1, p2], bi (15, 6) int
    [start, end, kind, parent, root, inversions], bf (15,) beam lengths, px/py (12,)
    positions at angle 0 and ux/uy (15,) crank and extension directions at angle 0.
    Triangle: a=A, c=C, dir, p0=l1, p1=l2, p2=backup angle. Extension: a=parent beam,
    c=inverted, p0=length. Static: p0=x, p1=y. Crank tip: p0=crank length. An extension's
    root is the crank or triangle beam its chain of parents starts from, and inversions
    counts the inverted links on that chain (its angle is the root's plus that many pi).
    """
    ni[:] = -1
    nf[:] = 0.0
    bi[:] = -1
    bf[:] = 0.0
    ni[0, 0] = MOTOR
    px[0] = 0.0
    py[0] = 0.0
    for s in range(3):
        ni[1 + s, 0] = STATIC
        x = float(int(g[2 * s] * 11) - 5)
        y = float(int(g[2 * s + 1] * 11) - 5)
        nf[1 + s, 0] = x
        nf[1 + s, 1] = y
        px[1 + s] = x
        py[1 + s] = y
    crank = 2.0 + 6.0 * g[CRANK_GENE]
    ni[4, 0] = CRANK
    nf[4, 0] = crank
    px[4] = crank
    py[4] = 0.0
    set_beam(bi, bf, 0, 0, 4, B_CRANK, -1, crank)
    bi[0, 4] = 0
    bi[0, 5] = 0
    ux[0] = 1.0
    uy[0] = 0.0
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
            bi[n_beams, 4] = parent if bi[parent, 2] != B_EXTENSION else bi[parent, 4]
            bi[n_beams, 5] = inverted + (bi[parent, 5] if bi[parent, 2] == B_EXTENSION else 0)
            place_extension(new, n_beams, ni, nf, bi, px, py, ux, uy)
            n_beams += 1
        else:
            a = int(g[o + 1] * (n_nodes - 1)) + 1
            c = int(g[o + 2] * (n_nodes - 1)) + 1
            c = repair_anchor(a, c, n_nodes, px, py)
            direction = int(g[o + 3] * 2)
            backup = 2.0 * math.pi * g[o + 4]
            d = math.sqrt((px[a] - px[c]) ** 2 + (py[a] - py[c]) ** 2)
            s1 = max(d - L_MAX, L_MIN)
            l1 = (L_MAX - s1) * g[o + 5] + s1
            lo = abs(d - l1)
            hi = min(d + l1, L_MAX)
            l2 = (hi - lo) * g[o + 6] + lo
            ni[new, 0] = TRIANGLE
            ni[new, 1] = a
            ni[new, 2] = c
            ni[new, 3] = direction
            nf[new, 0] = l1
            nf[new, 1] = l2
            nf[new, 2] = backup
            _, px[new], py[new] = circle_intersection(
                px[a], py[a], px[c], py[c], l1, l2, direction, backup, legacy
            )
            set_beam(bi, bf, n_beams, a, new, B_TRIANGLE, -1, l1)
            set_beam(bi, bf, n_beams + 1, c, new, B_TRIANGLE, -1, l2)
            n_beams += 2
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
def solve_angle(cos_t, sin_t, ni, nf, bi, legacy, px, py, ux, uy):
    """Places every node for a crank direction (cos_t, sin_t); False if a triangle fails."""
    crank = nf[4, 0]
    px[4] = crank * cos_t
    py[4] = crank * sin_t
    ux[0] = cos_t
    uy[0] = sin_t
    b = 1
    for new in range(5, N_NODES):
        if ni[new, 0] == EXTENSION:
            place_extension(new, b, ni, nf, bi, px, py, ux, uy)
            b += 1
        else:
            a = ni[new, 1]
            c = ni[new, 2]
            ok, x, y = circle_intersection(
                px[a], py[a], px[c], py[c], nf[new, 0], nf[new, 1], ni[new, 3], nf[new, 2], legacy
            )
            if not ok:
                return False
            px[new] = x
            py[new] = y
            b += 2
    return True


@numba.njit(**_JIT)
def simulate_one(ni, nf, bi, px, py, ux, uy, theta, cos_t, sin_t, legacy, xs, ys, valid):
    """Simulates one decoded linkage over the crank angles theta (A,); returns the error.

    px/py (12,) hold the positions at angle 0 (static nodes are read from them) and are
    overwritten; ux/uy (15,) are scratch; cos_t/sin_t (A,) are theta's cosines and sines.
    xs/ys (12, A) receive positions (NaN at failed angles), valid (A,) per-angle success.
    """
    error = 0
    for k in range(theta.shape[0]):
        ok = solve_angle(cos_t[k], sin_t[k], ni, nf, bi, legacy, px, py, ux, uy)
        valid[k] = ok
        if not ok:
            error += 1
        for j in range(N_NODES):
            xs[j, k] = px[j] if ok else np.nan
            ys[j, k] = py[j] if ok else np.nan
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
def points_up(foot, k, ni, bi, n_beams, xs, ys, theta):
    """Returns whether the mean recorded angle of the foot's beams lies in (0, pi)."""
    if ni[foot, 0] == TRIANGLE:
        a = ni[foot, 1]
        c = ni[foot, 2]
        dxa = xs[foot, k] - xs[a, k]
        dya = ys[foot, k] - ys[a, k]
        dxc = xs[foot, k] - xs[c, k]
        dyc = ys[foot, k] - ys[c, k]
        # Both beams pointing down: both atan2 values lie in [-pi, 0), so the mean is
        # negative. Both clearly up: both lie strictly inside (0, pi). Only the rest
        # needs the angles themselves.
        if dya < 0.0 and dyc < 0.0:
            return False
        if dya > 1e-9 * abs(dxa) and dyc > 1e-9 * abs(dxc):
            return True
    s = 0.0
    m = 0
    for b in range(n_beams):
        if bi[b, 1] == foot:
            s += recorded_angle(b, k, bi, xs, ys, theta)
            m += 1
    if m == 0:
        return False
    mean = s / m
    return 0.0 < mean < math.pi


@numba.njit(**_JIT)
def angle_error(foot, ni, bi, n_beams, xs, ys, valid, theta, legacy):
    """Returns F_ae for one simulated linkage (paper: count; legacy: distance-weighted)."""
    n_angles = valid.shape[0]
    if ni[foot, 0] in (MOTOR, STATIC):
        return 0.0
    total = 0.0
    prev = -1
    for k in range(n_angles - 1, -1, -1):
        if valid[k]:
            prev = k
            break
    for k in range(n_angles):
        if not valid[k]:
            continue
        if points_up(foot, k, ni, bi, n_beams, xs, ys, theta):
            if legacy:
                total += math.sqrt(
                    (xs[foot, k] - xs[foot, prev]) ** 2 + (ys[foot, k] - ys[foot, prev]) ** 2
                )
            else:
                total += 1.0
        prev = k
    return total


@numba.njit(**_JIT)
def find_foot(ys, valid):
    """Returns the index of the node with the lowest recorded y (first on ties)."""
    foot = 0
    best = np.inf
    for j in range(ys.shape[0]):
        for k in range(ys.shape[1]):
            if valid[k] and ys[j, k] < best:
                best = ys[j, k]
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
def point_distance(px, py, n, targets, use, cx, cy):
    """Returns sum over targets t with use[t] of min over samples of |t - (p - centroid)|."""
    total = 0.0
    for t in range(targets.shape[0]):
        if not use[t]:
            continue
        best = np.inf
        tx = targets[t, 0]
        ty = targets[t, 1]
        for i in range(n):
            ex = tx - (px[i] - cx)
            ey = ty - (py[i] - cy)
            d2 = ex * ex + ey * ey
            if d2 < best:
                best = d2
        total += math.sqrt(best)
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
    dx_low = px[(low + 1) % n] - px[low]
    stance = -1.0 if dx_low < 0.0 else 1.0
    f_s = 0.0
    f_l = 0.0
    for i in range(n):
        j = (i + 1) % n
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
    is_lift = ~is_step
    all_targets = np.ones(targets.shape[0], np.bool_)
    for chunk in numba.prange(n_chunks):
        ni = np.empty((N_NODES, 4), np.int64)
        nf = np.empty((N_NODES, 3))
        bi = np.empty((MAX_BEAMS, 6), np.int64)
        bf = np.empty(MAX_BEAMS)
        px0 = np.empty(N_NODES)
        py0 = np.empty(N_NODES)
        ux = np.empty(MAX_BEAMS)
        uy = np.empty(MAX_BEAMS)
        graph = np.empty((N_NODES, 5), np.int64)
        xs = np.empty((N_NODES, n_angles))
        ys = np.empty((N_NODES, n_angles))
        px = np.empty(n_angles)
        py = np.empty(n_angles)
        for i in range(chunk * n // n_chunks, (chunk + 1) * n // n_chunks):
            n_beams = decode_one(genomes[i], legacy, ni, nf, bi, bf, px0, py0, ux, uy)
            err = simulate_one(
                ni, nf, bi, px0, py0, ux, uy, theta, cos_t, sin_t, legacy, xs, ys, valid[i]
            )
            f = find_foot(ys, valid[i])
            ae = angle_error(f, ni, bi, n_beams, xs, ys, valid[i], theta, legacy)
            error[i] = err
            foot[i] = f
            angle_err[i] = ae
            for k in range(n_angles):
                foot_x[i, k] = xs[f, k]
                foot_y[i, k] = ys[f, k]
            m = compact_path(xs[f], ys[f], valid[i], px, py)
            cx = 0.0
            cy = 0.0
            x_lo = np.inf
            x_hi = -np.inf
            y_lo = np.inf
            y_hi = -np.inf
            for k in range(m):
                cx += px[k]
                cy += py[k]
                x_lo = min(x_lo, px[k])
                x_hi = max(x_hi, px[k])
                y_lo = min(y_lo, py[k])
                y_hi = max(y_hi, py[k])
            cx /= m
            cy /= m
            f_s, f_l = step_and_lift(px, py, m)
            penalty = err + ae
            if fitness == FP:
                loss[i, 0] = point_distance(px, py, m, targets, all_targets, cx, cy) + penalty
            elif fitness == FP2:
                loss[i, 0] = point_distance(px, py, m, targets, is_step, cx, cy) + penalty
                loss[i, 1] = point_distance(px, py, m, targets, is_lift, cx, cy) + penalty
            elif fitness == FSL:
                loss[i, 0] = -0.8 * f_s - 0.2 * f_l + penalty
            else:
                loss[i, 0] = -f_s + penalty
                loss[i, 1] = -f_l + penalty
            wh[i, 0] = y_hi - y_lo
            wh[i, 1] = x_hi - x_lo
            structure(ni, bi, bf, n_beams, f, graph, st[i])
            lis[i, 0] = st[i, 0]
            lis[i, 1] = f_l


@numba.njit(parallel=True, **_JIT)
def decode_batch(genomes, legacy, ni, nf, bi, bf, n_beams, pos0):
    """Decodes every genome at angle 0 into the packed topology arrays (see decode.py)."""
    for i in numba.prange(genomes.shape[0]):
        px = np.empty(N_NODES)
        py = np.empty(N_NODES)
        ux = np.empty(MAX_BEAMS)
        uy = np.empty(MAX_BEAMS)
        n_beams[i] = decode_one(genomes[i], legacy, ni[i], nf[i], bi[i], bf[i], px, py, ux, uy)
        pos0[i, :, 0] = px
        pos0[i, :, 1] = py


@numba.njit(parallel=True, **_JIT)
def simulate_batch(ni, nf, bi, n_beams, pos0, n_angles, legacy, positions, valid, bang, foot):
    """Simulates decoded linkages: positions (N, 12, A, 2), valid (N, A), bang (N, 15, A)."""
    theta = crank_angles(n_angles, legacy)
    cos_t = np.cos(theta)
    sin_t = np.sin(theta)
    for i in numba.prange(ni.shape[0]):
        xs = np.empty((N_NODES, n_angles))
        ys = np.empty((N_NODES, n_angles))
        simulate_one(
            ni[i], nf[i], bi[i], pos0[i, :, 0].copy(), pos0[i, :, 1].copy(),
            np.empty(MAX_BEAMS), np.empty(MAX_BEAMS), theta, cos_t, sin_t, legacy, xs, ys,
            valid[i],
        )  # fmt: skip
        foot[i] = find_foot(ys, valid[i])
        for k in range(n_angles):
            if valid[i, k]:
                for b in range(n_beams[i]):
                    bang[i, b, k] = recorded_angle(b, k, bi[i], xs, ys, theta)
        positions[i, :, :, 0] = xs
        positions[i, :, :, 1] = ys
