"""Provides the kernels that measure one simulated linkage: its foot, the angle error F_ae,
the foot path, F_p and F_sl, and the descriptors.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from linkevo.sim.linkage.genome import N_NODES
from linkevo.sim.linkage.kernels.codes import (
    B_CRANK,
    BAND,
    CRANK_TIP,
    MOTOR,
    NAN_OR_ONE,
    STATIC,
    TRIANGLE,
)
from linkevo.sim.linkage.kernels.jit import _INLINE, _JIT


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
