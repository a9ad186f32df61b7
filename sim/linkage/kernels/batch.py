"""Provides the batch entry points (`prange` over chunks of a batch): decode, simulate, evaluate;
`sim.linkage.decoding`, `sim.linkage.kinematics` and `sim.linkage.evaluating` are their numpy faces.

The kernels' argument lists of 15-30 arrays are laid out by hand (ruff told to skip them): one
argument per line, as ruff would lay them out, spreads each call over a screen.
"""

from __future__ import annotations

import numba
import numpy as np

from linkevo.sim.linkage.genome import MAX_BEAMS, N_NODES
from linkevo.sim.linkage.kernels.codes import FP, FP2, FSL
from linkevo.sim.linkage.kernels.geometry import crank_angles
from linkevo.sim.linkage.kernels.jit import _BATCH, _JIT
from linkevo.sim.linkage.kernels.measures import (
    angle_error,
    find_foot,
    foot_path,
    nearest_distance,
    path_extent,
    recorded_angle,
    step_and_lift,
    structure,
    summed_distance,
)
from linkevo.sim.linkage.kernels.placement import decode_and_simulate, place_motor, simulate_one


@numba.njit(parallel=True, **_BATCH)
def evaluate_batch(
    genomes, legacy, n_angles, fitness, targets, is_step, n_chunks,
    loss, error, angle_err, valid, foot, foot_x, foot_y, wh, lis, st,
    keep, ni_out, nf_out, bi_out, bf_out, nb_out, pos0_out, positions_out, bang_out,
):  # fmt: skip
    """Decodes, simulates and scores every genome; writes into the output arrays.

    genomes (N, 56); targets (P, 2); is_step (P,) bool; loss (N, 1) or (N, 2); error,
    foot (N,) int; angle_err (N,); valid (N, A); foot_x, foot_y (N, A); wh, lis (N, 2);
    st (N, 4). The batch is split into n_chunks contiguous chunks that share scratch.
    With `keep`, every linkage's decoding and motion go into the `*_out` arrays as
    `decode_batch` and `simulate_batch` write them (ni_out (N, 12, 4), nf_out (N, 12, 5),
    bi_out (N, 15, 6), bf_out (N, 15), nb_out (N,), pos0_out (N, 12, 2), positions_out
    (N, 12, A, 2), bang_out (N, 15, A) NaN-filled); without it they may be empty.
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
            if keep:
                _keep(i, ni, nf, bi, bf, n_beams, xs, ys, ok, theta, ni_out, nf_out, bi_out,
                      bf_out, nb_out, pos0_out, positions_out, bang_out)  # fmt: skip
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


@numba.njit(**_JIT)
def _keep(
    i,
    ni,
    nf,
    bi,
    bf,
    n_beams,
    xs,
    ys,
    ok,
    theta,
    ni_out,
    nf_out,
    bi_out,
    bf_out,
    nb_out,
    pos0_out,
    positions_out,
    bang_out,
):
    """Writes linkage i's decoding and motion into the batch's arrays (`evaluate_batch`)."""
    for j in range(ni.shape[0]):
        for c in range(ni.shape[1]):
            ni_out[i, j, c] = ni[j, c]
        for c in range(nf.shape[1]):
            nf_out[i, j, c] = nf[j, c]
        pos0_out[i, j, 0] = xs[j, 0]
        pos0_out[i, j, 1] = ys[j, 0]
    for b in range(bi.shape[0]):
        for c in range(bi.shape[1]):
            bi_out[i, b, c] = bi[b, c]
        bf_out[i, b] = bf[b]
    nb_out[i] = n_beams
    for k in range(xs.shape[1]):
        if ok[k]:
            for b in range(n_beams):
                bang_out[i, b, k] = recorded_angle(b, k, bi, xs, ys, theta)
        for j in range(xs.shape[0]):
            positions_out[i, j, k, 0] = xs[j, k] if ok[k] else np.nan
            positions_out[i, j, k, 1] = ys[j, k] if ok[k] else np.nan


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
def simulate_batch(ni, nf, bi, n_beams, theta, legacy, positions, valid, bang, foot):
    """Simulates decoded linkages at crank angles theta (A,) (`crank_angles`, or some of
    them): positions (N, 12, A, 2), valid (N, A), bang (N, 15, A).

    Positions at failed angles are NaN.
    """
    n_angles = theta.shape[0]
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
