"""Provides `round_batch`: the whole-module rounding of each linkage of a batch (the LEGO
build `sim.robot.lego.quantise` chooses) by a depth-first search, in well under a millisecond a
linkage, for the walk model's inputs (`sim.robot.builds`).

`quantise` simulates every rounding (each beam down or up, at least 1 module) at the
coarse crank angles and takes, closest foot path first, the first that turns with rigid
beams over the whole turn. Here the nodes are placed one at a time, each beam choice
once for every rounding that shares the beams before it (the kernels of `placement`, so
the positions are those of `simulate`, bit for bit), and a node that fails to assemble or
stretches a beam at a coarse angle cuts off every rounding below it, as does one too far
from the original foot path for the foot, at most its beams' length away, to come within
the `keep` closest found so far. The foot's position
depends only on the beams of its ancestors ("foot beams"), so the search runs in two
stages: every assignment of the foot beams, keeping the `keep` closest foot paths in
product order; then, for each of those in order, the other beams in product order, until
a rounding turns over the whole turn with rigid beams and keeps the foot node. That is
`quantise`'s choice unless its answer lies beyond the `keep` closest foot paths, moves the
foot to another node, or ties with another in floating point (0.5-6 % of study linkages);
a linkage with no rounding found gets -1.

The kernels' argument lists of 15-30 arrays are laid out by hand (ruff told to skip them): one
argument per line, as ruff would lay them out, spreads each call over a screen.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from linkevo.sim.linkage.genome import MAX_BEAMS, N_NODES
from linkevo.sim.linkage.kernels.codes import CRANK_TIP, EXACT, EXTENSION, TRIANGLE
from linkevo.sim.linkage.kernels.jit import _BATCH
from linkevo.sim.linkage.kernels.measures import find_foot
from linkevo.sim.linkage.kernels.placement import (
    place_base,
    place_extension,
    place_motor,
    place_triangle,
    simulate_one,
)


@numba.njit(**_BATCH)
def _set_lengths(j, l1, l2, ni, nf):
    """Writes node j's beam lengths l1 (and a triangle's l2) into its parameters nf (12, 5),
    with a triangle's backup point as `sim.linkage.decoding` writes it."""
    nf[j, 0] = l1
    if j == CRANK_TIP or ni[j, 0] == EXTENSION:
        return
    nf[j, 1] = l2
    same = l1 == l2
    nf[j, 3] = l1 * math.cos(nf[j, 2]) if same else 0.0
    nf[j, 4] = l1 * math.sin(nf[j, 2]) if same else 0.0


@numba.njit(**_BATCH)
def _place(j, b1, b2, ni, nf, bi, legacy, cos_t, sin_t, xs, ys, ux, uy, ok, lengths):
    """Places node j at every column of xs/ys (12, A); returns True when it assembles at
    every angle and its beams b1, b2 (-1: none) keep their `lengths` (15,)."""
    n = xs.shape[1]
    if j == CRANK_TIP:
        place_base(nf, cos_t, sin_t, xs, ys)
        return True
    if ni[j, 0] == EXTENSION:
        place_extension(j, b1, ni, nf, bi, xs, ys, ux, uy, n)
        return True
    ok[:] = True
    place_triangle(j, ni, nf, legacy, xs, ys, ok)
    for k in range(n):
        if not ok[k]:
            return False
    for b in (b1, b2):  # |d - l| = |d^2 - l^2| / (d + l): no square root
        s = bi[b, 0]
        square = lengths[b] * lengths[b]
        worst = 0.0
        for k in range(n):
            dx = xs[j, k] - xs[s, k]
            dy = ys[j, k] - ys[s, k]
            worst = max(worst, abs(dx * dx + dy * dy - square))
        if worst > 2.0 * EXACT * lengths[b]:
            return False
    return True


@numba.njit(**_BATCH)
def _rigid_turn(ni, nf, bi, n_beams, lengths, cos_f, sin_f, legacy, fx, fy, fux, fuy, fok):
    """True when the linkage turns at every angle of cos_f/sin_f (the whole turn) with
    every beam at its length."""
    if simulate_one(ni, nf, bi, cos_f, sin_f, legacy, fx, fy, fux, fuy, fok) > 0:
        return False
    for b in range(n_beams):
        s = bi[b, 0]
        e = bi[b, 1]
        for k in range(fx.shape[1]):
            d = math.sqrt((fx[e, k] - fx[s, k]) ** 2 + (fy[e, k] - fy[s, k]) ** 2)
            if abs(d - lengths[b]) > EXACT:
                return False
    return True


@numba.njit(**_BATCH)
def _choose(j, c, nb1, nb2, lo, hi, lengths):
    """Sets node j's beams to their c-th rounding in product order (first beam slowest)."""
    b1 = nb1[j]
    b2 = nb2[j]
    two = b2 >= 0 and lo[b2] != hi[b2]
    first = c // 2 if two else c
    lengths[b1] = hi[b1] if first else lo[b1]
    if b2 >= 0:
        lengths[b2] = hi[b2] if (two and c % 2) else lo[b2]


@numba.njit(**_BATCH)
def _search(nodes, count, nb1, nb2, lo, hi, ni, nf, bi, legacy, cos_t, sin_t, xs, ys, ux, uy,
            ok, lengths, foot, ref_x, ref_y, seen, best_d, best_l, first_only, n_beams,
            cos_f, sin_f, fx, fy, fux, fuy, fok, reach):  # fmt: skip
    """Depth-first over the roundings of the beams of `nodes` (count of them, in order).

    first_only False: every rounding's foot distance (mean over the `seen` coarse angles
    from ref_x/ref_y) is ranked into best_d (K,) / best_l (K, 15), earlier roundings first
    on ties, and a node whose `reach` (12,) (the furthest the foot can be from it) cannot
    bring the foot within the K-th closest cuts off its roundings; returns False.
    first_only True: returns True at the first rounding (with
    `lengths` holding it) that keeps the foot node and turns rigidly over the whole turn.
    """
    if count == 0:
        return first_only and _rigid_turn(
            ni, nf, bi, n_beams, lengths, cos_f, sin_f, legacy, fx, fy, fux, fuy, fok
        )
    combos = np.empty(count, np.int64)
    for level in range(count):
        j = nodes[level]
        c = 1 if lo[nb1[j]] == hi[nb1[j]] else 2
        combos[level] = c * 2 if nb2[j] >= 0 and lo[nb2[j]] != hi[nb2[j]] else c
    n_seen = max(np.sum(seen), 1)
    choice = np.zeros(count, np.int64)
    lows = np.empty(xs.shape[1])
    rows = np.empty(xs.shape[1], np.int64)
    level = 0
    while True:
        j = nodes[level]
        _choose(j, choice[level], nb1, nb2, lo, hi, lengths)
        _set_lengths(j, lengths[nb1[j]], lengths[nb2[j]] if nb2[j] >= 0 else 0.0, ni, nf)
        good = _place(
            j, nb1[j], nb2[j], ni, nf, bi, legacy, cos_t, sin_t, xs, ys, ux, uy, ok, lengths
        )
        if good and not first_only and level < count - 1 and np.isfinite(best_d[-1]):
            r = reach[j]
            if r < np.inf:  # the foot is within r of node j: a lower bound of its distance
                bound = 0.0
                for k in range(xs.shape[1]):
                    if seen[k]:
                        dx = xs[j, k] - ref_x[k]
                        dy = ys[j, k] - ref_y[k]
                        bound += max(math.sqrt(dx * dx + dy * dy) - r, 0.0)
                good = bound / n_seen < best_d[-1]
        if good and level == count - 1:
            good = False  # a leaf: ranked or tried, then the next rounding
            if first_only:
                ok[:] = True
                if find_foot(ys, ok, lows, rows) == foot and _rigid_turn(
                    ni, nf, bi, n_beams, lengths, cos_f, sin_f, legacy, fx, fy, fux, fuy, fok
                ):
                    return True
            else:
                bar = best_d[-1] * n_seen
                total = 0.0
                for k in range(xs.shape[1]):
                    if seen[k] and total <= bar:
                        dx = xs[foot, k] - ref_x[k]
                        dy = ys[foot, k] - ref_y[k]
                        total += math.sqrt(dx * dx + dy * dy)
                d = total / n_seen
                at = best_d.shape[0]
                while at > 0 and d < best_d[at - 1]:
                    at -= 1
                if at < best_d.shape[0]:
                    for q in range(best_d.shape[0] - 1, at, -1):
                        best_d[q] = best_d[q - 1]
                        best_l[q] = best_l[q - 1]
                    best_d[at] = d
                    best_l[at] = lengths
        if good:
            level += 1
            choice[level] = 0
            continue
        while True:  # the next rounding: the deepest level with a choice left
            choice[level] += 1
            if choice[level] < combos[level]:
                break
            if level == 0:
                return False
            level -= 1


@numba.njit(**_BATCH)
def round_batch(ni_all, nf_all, bi_all, n_beams_all, length_all, foot_all, legacy, theta,
                theta_full, ref_x_all, ref_y_all, seen_all, keep, out):  # fmt: skip
    """Writes out (N, 15): each linkage's whole-module beam lengths, -1 where none found.

    The batch's packed tables (`sim.linkage.decoding`: ni (N, 12, 4), nf (N, 12, 5), bi (N, 15, 6),
    n_beams (N,), lengths (N, 15)); foot_all (N,) each original's foot node; theta (C,) the
    coarse crank angles and theta_full (A,) the whole turn's; ref_x/ref_y (N, C) the
    original foot path at the coarse angles, seen (N, C) where it assembles there; keep:
    the foot-beam roundings tried (closest foot paths first).
    """
    n_coarse = theta.shape[0]
    n_full = theta_full.shape[0]
    cos_t = np.cos(theta)
    sin_t = np.sin(theta)
    cos_f = np.cos(theta_full)
    sin_f = np.sin(theta_full)
    xs = np.empty((N_NODES, n_coarse))
    ys = np.empty((N_NODES, n_coarse))
    ux = np.empty((MAX_BEAMS, n_coarse))
    uy = np.empty((MAX_BEAMS, n_coarse))
    ok = np.empty(n_coarse, np.bool_)
    fx = np.empty((N_NODES, n_full))
    fy = np.empty((N_NODES, n_full))
    fux = np.empty((MAX_BEAMS, n_full))
    fuy = np.empty((MAX_BEAMS, n_full))
    fok = np.empty(n_full, np.bool_)
    place_motor(cos_t, sin_t, xs, ys, ux, uy)
    place_motor(cos_f, sin_f, fx, fy, fux, fuy)
    lo = np.empty(MAX_BEAMS)
    hi = np.empty(MAX_BEAMS)
    lengths = np.empty(MAX_BEAMS)
    nb1 = np.empty(N_NODES, np.int64)
    nb2 = np.empty(N_NODES, np.int64)
    ancestor = np.empty(N_NODES, np.bool_)
    foot_nodes = np.empty(N_NODES, np.int64)
    other_nodes = np.empty(N_NODES, np.int64)
    best_d = np.empty(keep)
    best_l = np.empty((keep, MAX_BEAMS))
    reach = np.empty(N_NODES)
    for i in range(ni_all.shape[0]):
        ni = ni_all[i]
        nf = nf_all[i].copy()
        bi = bi_all[i]
        n_beams = n_beams_all[i]
        foot = foot_all[i]
        out[i, :] = -1.0
        place_base(nf, cos_t, sin_t, xs, ys)
        nb1[:] = -1
        nb2[:] = -1
        lengths[:] = 0.0
        for b in range(n_beams):
            length = length_all[i, b]
            lengths[b] = length
            lo[b] = max(math.floor(length), 1.0)
            hi[b] = max(math.ceil(length), 1.0)
            e = bi[b, 1]
            if nb1[e] < 0:
                nb1[e] = b
            else:
                nb2[e] = b
        ancestor[:] = False
        ancestor[foot] = True
        ancestor[CRANK_TIP] = True
        for j in range(N_NODES - 1, CRANK_TIP, -1):
            if not ancestor[j]:
                continue
            if ni[j, 0] == TRIANGLE:
                ancestor[ni[j, 1]] = True
                ancestor[ni[j, 2]] = True
            else:  # an extension: its start and its parent beam's ends
                p = ni[j, 1]
                ancestor[bi[p, 0]] = True
                ancestor[bi[p, 1]] = True
                ancestor[bi[nb1[j], 0]] = True
        reach[:] = np.inf  # along the beams, each at its longer rounding
        reach[foot] = 0.0
        for j in range(N_NODES - 1, CRANK_TIP, -1):
            if ancestor[j] and reach[j] < np.inf:
                b = nb1[j]
                start = ni[j, 1] if ni[j, 0] == TRIANGLE else bi[b, 0]
                reach[start] = min(reach[start], reach[j] + hi[b])
                if ni[j, 0] == TRIANGLE:
                    reach[ni[j, 2]] = min(reach[ni[j, 2]], reach[j] + hi[nb2[j]])
        n_foot = 0
        n_other = 0
        for j in range(CRANK_TIP, N_NODES):
            if ancestor[j]:
                foot_nodes[n_foot] = j
                n_foot += 1
            else:
                other_nodes[n_other] = j
                n_other += 1
        best_d[:] = np.inf
        _search(foot_nodes, n_foot, nb1, nb2, lo, hi, ni, nf, bi, legacy, cos_t, sin_t, xs, ys,
                ux, uy, ok, lengths, foot, ref_x_all[i], ref_y_all[i], seen_all[i], best_d,
                best_l, False, n_beams, cos_f, sin_f, fx, fy, fux, fuy, fok, reach)  # fmt: skip
        for q in range(keep):
            if not np.isfinite(best_d[q]):
                break
            lengths[:] = best_l[q]
            for level in range(n_foot):  # the foot beams as ranked, placed again
                j = foot_nodes[level]
                _set_lengths(j, lengths[nb1[j]], lengths[nb2[j]] if nb2[j] >= 0 else 0.0, ni, nf)
                _place(
                    j, nb1[j], nb2[j], ni, nf, bi, legacy, cos_t, sin_t, xs, ys, ux, uy, ok, lengths
                )
            if _search(other_nodes, n_other, nb1, nb2, lo, hi, ni, nf, bi, legacy, cos_t,
                       sin_t, xs, ys, ux, uy, ok, lengths, foot, ref_x_all[i], ref_y_all[i],
                       seen_all[i], best_d, best_l, True, n_beams, cos_f, sin_f, fx, fy, fux,
                       fuy, fok, reach):  # fmt: skip
                out[i, :n_beams] = lengths[:n_beams]
                break
