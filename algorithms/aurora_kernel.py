"""Provides the compiled CPU training epoch of the path autoencoder (Adagrad on the MAE).

One call runs a whole epoch: every batch's forward pass, the hand-written backward pass
and the Adagrad update, over preallocated float32 buffers, with no Python or framework
call per step. A step is about 4 MFLOP on matrices of at most 80 x 64, where a framework's
per-operation overhead, not the arithmetic, is most of the time.

Layout: the parameters are one flat float32 vector (layer i's weight (out, in) row-major,
then its bias), as `PathAutoencoder` keeps them. Activations are feature-major, (units,
C) with C = the batch rounded up to a multiple of 16 lanes, so that the forward and the
input-gradient loops run along the batch in whole vectors; padding columns carry zero
gradient. The weight gradient reads a batch-major copy of each layer's input.

Every sum runs in the order the loops write it, on any CPU: the kernels compile without
reassociation and without fused multiply-adds, so LLVM may spread a loop over vector
lanes (the batch columns, each summed on its own) but never regroups a sum or fuses a
product into it. Training and encoding therefore give the same bits for a seed on every
x86-64 CPU numba compiles for, from the baseline x86-64 to AVX-512
(`tests/algorithms/test_aurora_reproducible.py`); docs/aurora.md gives the cost.
"""

from __future__ import annotations

import numba
import numpy as np

from linkevo.sim.linkage.kernels import NOALIAS

LANES = 16
"""float32 lanes of one 512-bit vector: the batch is padded to a multiple of this."""
ROWS = 4
"""Output rows computed together; a width's remainder rows are computed one by one."""

_FLAGS = {"fastmath": False, "error_model": "numpy", "cache": True}
"""IEEE arithmetic in the written order: no reassociated sums, no fused multiply-adds, so
the bits do not depend on the CPU's vector width or on whether it has FMA."""
_HELPER = {**_FLAGS, "_nrt": False, "forceinline": True, **NOALIAS}
"""Helpers are inlined by LLVM with their arrays `noalias` (see `sim.linkage.kernels._JIT`), which
lets LLVM keep each row's sums in registers."""


@numba.njit(**_HELPER)
def multiply_add(a, bias, x, y, n_rows, n_k, n_blocks):
    """Writes y (n_rows, C) = a (n_rows, n_k) @ x (n_k, C) + bias (n_rows,) broadcast
    along each row, over the first n_blocks blocks of LANES columns."""
    for c in range(n_blocks):
        c0 = c * LANES
        for j in range(0, n_rows - ROWS + 1, ROWS):
            for b in range(LANES):
                for r in range(ROWS):
                    y[j + r, c0 + b] = bias[j + r]
            for i in range(n_k):
                a0 = a[j, i]
                a1 = a[j + 1, i]
                a2 = a[j + 2, i]
                a3 = a[j + 3, i]
                for b in range(LANES):
                    v = x[i, c0 + b]
                    y[j, c0 + b] += a0 * v
                    y[j + 1, c0 + b] += a1 * v
                    y[j + 2, c0 + b] += a2 * v
                    y[j + 3, c0 + b] += a3 * v
        for j in range(n_rows - n_rows % ROWS, n_rows):
            for b in range(LANES):
                y[j, c0 + b] = bias[j]
            for i in range(n_k):
                a0 = a[j, i]
                for b in range(LANES):
                    y[j, c0 + b] += a0 * x[i, c0 + b]


@numba.njit(**_HELPER)
def input_gradient(w, g, g_in, n_in, n_out, n_blocks):
    """Writes g_in (n_in, C) = w.T (n_in, n_out) @ g (n_out, C)."""
    for c in range(n_blocks):
        c0 = c * LANES
        for i in range(0, n_in - ROWS + 1, ROWS):
            for b in range(LANES):
                for r in range(ROWS):
                    g_in[i + r, c0 + b] = 0.0
            for j in range(n_out):
                w0 = w[j, i]
                w1 = w[j, i + 1]
                w2 = w[j, i + 2]
                w3 = w[j, i + 3]
                for b in range(LANES):
                    v = g[j, c0 + b]
                    g_in[i, c0 + b] += w0 * v
                    g_in[i + 1, c0 + b] += w1 * v
                    g_in[i + 2, c0 + b] += w2 * v
                    g_in[i + 3, c0 + b] += w3 * v
        for i in range(n_in - n_in % ROWS, n_in):
            for b in range(LANES):
                g_in[i, c0 + b] = 0.0
            for j in range(n_out):
                w0 = w[j, i]
                for b in range(LANES):
                    g_in[i, c0 + b] += w0 * g[j, c0 + b]


@numba.njit(**_HELPER)
def adagrad_layer(w, w_sum, bias, b_sum, g, x, x_t, grad, zeros, n_in, n_out, n_cols, lr, eps):
    """Takes one layer's Adagrad step, sum += grad^2; param -= lr * grad / (sqrt(sum) +
    eps), with the gradients g (n_out, C) @ x.T of w and g's row sums of bias. x_t
    (C, >= n_in rounded up to LANES) and grad (>= n_out, same) are scratch; zeros holds
    at least n_out zeros."""
    n_blocks = -(-n_in // LANES)
    for b in range(n_cols):
        for i in range(n_in):
            x_t[b, i] = x[i, b]
        for i in range(n_in, n_blocks * LANES):
            x_t[b, i] = 0.0
    multiply_add(g, zeros, x_t, grad, n_out, n_cols, n_blocks)
    for j in range(n_out):
        gb = np.float32(0.0)
        for b in range(n_cols):
            gb += g[j, b]
        s = b_sum[j] + gb * gb
        b_sum[j] = s
        bias[j] -= lr * gb / (np.sqrt(s) + eps)
        for i in range(n_in):
            s = w_sum[j, i] + grad[j, i] * grad[j, i]
            w_sum[j, i] = s
            w[j, i] -= lr * grad[j, i] / (np.sqrt(s) + eps)


@numba.njit(**_HELPER)
def forward(theta, sizes, stop, bottleneck, work, n_blocks):
    """Runs layers 0..stop-1 on the block in work[0], each layer's output in work[layer + 1]
    (layer bottleneck - 1 through the sigmoid); returns the parameter offset after them."""
    one = np.float32(1.0)
    offset = 0
    for layer in range(stop):
        n_in = sizes[layer]
        n_out = sizes[layer + 1]
        w = theta[offset : offset + n_in * n_out].reshape((n_out, n_in))
        bias = theta[offset + n_in * n_out : offset + n_in * n_out + n_out]
        y = work[layer + 1]
        multiply_add(w, bias, work[layer], y, n_out, n_in, n_blocks)
        if layer == bottleneck - 1:
            for j in range(n_out):
                for b in range(y.shape[1]):
                    y[j, b] = one / (one + np.exp(-y[j, b]))
        offset += n_in * n_out + n_out
    return offset


@numba.njit(**_FLAGS)
def train_epoch(
    theta, accumulator, data, order, batch_size, lr, eps, sizes, bottleneck, work, x_t, grad, zeros
):
    """Takes one epoch of Adagrad steps on the mean absolute error, updating theta and
    accumulator (P,) float32 in place.

    data (N, n) float32 holds the paths, order (N,) int64 the epoch's visiting order, in
    batches of batch_size (the last possibly smaller). sizes (L + 1,) are the layer widths,
    input to output; layer bottleneck - 1 ends in the sigmoid. work, x_t, grad and zeros
    are the scratch of `epoch_workspace`.
    """
    n = order.shape[0]
    n_layers = sizes.shape[0] - 1
    n_inputs = sizes[0]
    n_cols = work.shape[2]
    n_blocks = n_cols // LANES
    one = np.float32(1.0)
    for start in range(0, n, batch_size):
        m = min(batch_size, n - start)
        x0 = work[0]
        for b in range(n_cols):
            r = order[start + b] if b < m else 0
            for i in range(n_inputs):
                x0[i, b] = data[r, i] if b < m else 0.0
        offset = forward(theta, sizes, n_layers, bottleneck, work, n_blocks)
        out = work[n_layers]
        g = work[n_layers + 1]
        g_in = work[n_layers + 2]
        denominator = np.float32(m * n_inputs)
        for i in range(n_inputs):
            for b in range(n_cols):
                d = out[i, b] - x0[i, b]
                sign = one if d > 0.0 else (-one if d < 0.0 else np.float32(0.0))
                g[i, b] = sign / denominator if b < m else np.float32(0.0)
        for layer in range(n_layers - 1, -1, -1):
            n_in = sizes[layer]
            n_out = sizes[layer + 1]
            offset -= n_in * n_out + n_out
            if layer == bottleneck - 1:
                s = work[layer + 1]
                for j in range(n_out):
                    for b in range(n_cols):
                        g[j, b] = g[j, b] * (s[j, b] - s[j, b] * s[j, b])
            end_w = offset + n_in * n_out
            w = theta[offset:end_w].reshape((n_out, n_in))
            if layer > 0:
                input_gradient(w, g, g_in, n_in, n_out, n_blocks)
            adagrad_layer(
                w,
                accumulator[offset:end_w].reshape((n_out, n_in)),
                theta[end_w : end_w + n_out],
                accumulator[end_w : end_w + n_out],
                g,
                work[layer],
                x_t,
                grad,
                zeros,
                n_in,
                n_out,
                n_cols,
                lr,
                eps,
            )
            g, g_in = g_in, g


@numba.njit(**_FLAGS)
def encode_batch(theta, data, sizes, bottleneck, work, out):
    """Writes the bottleneck codes out (N, code) float64 of the paths data (N, n) float32:
    the encoder's layers (as `train_epoch` computes them) over blocks of work.shape[2]
    paths, with the scratch work of `epoch_workspace`."""
    n = data.shape[0]
    n_inputs = sizes[0]
    n_cols = work.shape[2]
    n_blocks = n_cols // LANES
    for start in range(0, n, n_cols):
        m = min(n_cols, n - start)
        x0 = work[0]
        for b in range(n_cols):
            for i in range(n_inputs):
                x0[i, b] = data[start + b, i] if b < m else 0.0
        forward(theta, sizes, bottleneck, bottleneck, work, n_blocks)
        code = work[bottleneck]
        for b in range(m):
            for j in range(sizes[bottleneck]):
                out[start + b, j] = code[j, b]


def epoch_workspace(sizes: tuple[int, ...], batch_size: int) -> tuple[np.ndarray, ...]:
    """Returns the float32 zeros `train_epoch` needs: work (L + 3, S, C), rows 0..L for
    the activations and L+1, L+2 for the gradients; x_t (C, S'), a layer's input
    batch-major; grad (S, S'), a weight gradient; zeros (S,). S = max(sizes), S' = S
    rounded up to a multiple of LANES, C = batch_size rounded up likewise.
    """
    n_cols = -(-batch_size // LANES) * LANES
    width = max(sizes)
    padded = -(-width // LANES) * LANES
    return (
        np.zeros((len(sizes) + 2, width, n_cols), dtype=np.float32),
        np.zeros((n_cols, padded), dtype=np.float32),
        np.zeros((width, padded), dtype=np.float32),
        np.zeros(width, dtype=np.float32),
    )
