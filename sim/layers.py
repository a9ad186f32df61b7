"""Provides the layer plan of a built linkage: beams that cross during the turn go on
different layers, with as few layers as possible.

Two beams conflict when, at any sampled crank angle, their segments cross (a proper
intersection: each segment's ends on opposite sides of the other's line), or when they
meet at a joint: a pin joins beams stacked on different layers. An extension and the beam
it continues are one straight beam (the sheet says so), so they share a layer instead.
The fewest layers is the chromatic number of the conflict graph, found exactly as a small
integer programme with `scipy.optimize.milp` (a linkage has at most 15 beams): binary
x[b, l] puts beam b on layer l, y[l] marks layer l used; each beam takes one layer, two
conflicting beams never share one, merged beams share theirs, layers are used in order
(y[l] >= y[l + 1]), and the sum of y is minimised.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, milp

from linkevo.sim.decoding import LinkageBatch
from linkevo.sim.kinematics import Motion

COLLINEAR = 1e-9
"""A cross product (square modules) below this is taken as zero: the points are collinear."""


@dataclass(frozen=True)
class LayerPlan:
    """The layers of one linkage's beams.

    Attributes:
        layer: (B,) int64 layer of each beam, 0 nearest the frame.
        n_layers: how many layers are used.
        crossings: (K, 2) int64 the beam pairs that cross at some sampled angle.
        joints: (J, 2) int64 the beam pairs that meet at a joint (on different layers).
        merged: (M, 2) int64 (extension, parent) pairs built as one beam (one layer).
    """

    layer: np.ndarray
    n_layers: int
    crossings: np.ndarray
    joints: np.ndarray
    merged: np.ndarray


def crossing_pairs(batch: LinkageBatch, motion: Motion, i: int = 0) -> np.ndarray:
    """Returns (K, 2) the pairs of linkage i's beams that cross at an assembled angle.

    Args:
        batch: decoded linkages; motion: their simulation (positions (N, 12, A, 2)).
        i: which linkage.
    """
    n_beams = int(batch.n_beams[i])
    start, end = batch.beam_int[i, :n_beams, 0], batch.beam_int[i, :n_beams, 1]
    pos = motion.positions[i][:, motion.valid[i]]  # (12, A', 2)
    p, q = pos[start], pos[end]  # (B, A', 2) each beam's ends
    a, b = np.triu_indices(n_beams, k=1)
    shared = (
        (start[a] == start[b]) | (start[a] == end[b]) | (end[a] == start[b]) | (end[a] == end[b])
    )
    a, b = a[~shared], b[~shared]

    def side(o, d, x):  # sign of the cross product (d - o) x (x - o), per pair and angle;
        # 0 within rounding (collinear beams, e.g. a beam and its extensions, never cross)
        value = (d[..., 0] - o[..., 0]) * (x[..., 1] - o[..., 1]) - (d[..., 1] - o[..., 1]) * (
            x[..., 0] - o[..., 0]
        )
        return np.where(np.abs(value) < COLLINEAR, 0.0, np.sign(value))

    cross = (side(p[a], q[a], p[b]) * side(p[a], q[a], q[b]) < 0) & (
        side(p[b], q[b], p[a]) * side(p[b], q[b], q[a]) < 0
    )  # (K, A')
    hit = cross.any(axis=1)
    return np.stack([a[hit], b[hit]], axis=1).astype(np.int64)


def min_layers(n_items: int, conflicts: np.ndarray, same: np.ndarray | None = None) -> np.ndarray:
    """Returns (n_items,) int64 layers using the fewest layers such that no conflicting
    pair (K, 2) shares one and every `same` pair (M, 2) does (an exact graph colouring,
    `scipy.optimize.milp`). Repertoire neighbours often share a graph, so colourings are
    cached by graph (the solve is most of a leg's layer plan)."""
    conflicts = np.asarray(conflicts, dtype=np.int64).reshape(-1, 2)
    same = np.zeros((0, 2), np.int64) if same is None else np.asarray(same, np.int64).reshape(-1, 2)
    key = (n_items, tuple(map(tuple, conflicts.tolist())), tuple(map(tuple, same.tolist())))
    return np.array(_colouring(*key), dtype=np.int64)


@functools.lru_cache(maxsize=4096)
def _colouring(
    n_items: int, conflicts: tuple[tuple[int, int], ...], same: tuple[tuple[int, int], ...]
) -> tuple[int, ...]:
    """`min_layers` on a hashable graph: the layer of each item."""
    if n_items == 0:
        return ()
    n_layers = n_items  # an upper bound: every item on its own layer
    nx = n_items * n_layers  # x[b, l] at b * n_layers + l, then y[l]
    rows, bounds_low, bounds_high = [], [], []

    def constraint(coefficients: dict[int, float], low: float, high: float) -> None:
        row = np.zeros(nx + n_layers)
        for k, v in coefficients.items():
            row[k] += v
        rows.append(row)
        bounds_low.append(low)
        bounds_high.append(high)

    for item in range(n_items):  # one layer each
        constraint({item * n_layers + layer: 1.0 for layer in range(n_layers)}, 1, 1)
        for layer in range(n_layers):  # only on a used layer
            constraint({item * n_layers + layer: 1.0, nx + layer: -1.0}, -np.inf, 0)
    for first, second in conflicts:
        for layer in range(n_layers):
            coefficients = {first * n_layers + layer: 1.0, second * n_layers + layer: 1.0}
            constraint({**coefficients, nx + layer: -1.0}, -np.inf, 0)
    for first, second in same:
        for layer in range(n_layers):
            constraint({first * n_layers + layer: 1.0, second * n_layers + layer: -1.0}, 0, 0)
    for layer in range(n_layers - 1):  # layers in order: no symmetric copies
        constraint({nx + layer: -1.0, nx + layer + 1: 1.0}, -np.inf, 0)
    cost = np.concatenate([np.zeros(nx), np.ones(n_layers)])
    result = milp(
        cost,
        constraints=LinearConstraint(np.array(rows), bounds_low, bounds_high),
        integrality=np.ones(nx + n_layers),
        bounds=Bounds(0, 1),
    )
    if not result.success:
        raise ValueError(f"no layer plan: a merged pair also conflicts ({result.message})")
    x = np.round(result.x[:nx]).reshape(n_items, n_layers)
    return tuple(int(v) for v in x.argmax(axis=1))


def layer_plan(batch: LinkageBatch, motion: Motion, i: int = 0) -> LayerPlan:
    """Returns the layer plan of linkage i (the fewest layers with no crossing or joint on
    one)."""
    n_beams = int(batch.n_beams[i])
    ends = batch.beam_int[i, :n_beams, :2]
    parent = batch.beam_int[i, :n_beams, 3]
    merged = np.array([(b, parent[b]) for b in range(n_beams) if parent[b] >= 0], np.int64)
    merged = merged.reshape(-1, 2)
    group = np.arange(n_beams)  # a beam and every extension of it: one straight beam
    for b, p in merged:
        group[b] = group[p]
    a, b = np.triu_indices(n_beams, k=1)
    meet = [
        bool(set(ends[x]) & set(ends[y])) and group[x] != group[y]
        for x, y in zip(a, b, strict=True)
    ]
    joints = np.stack([a[meet], b[meet]], axis=1).astype(np.int64)
    crossings = crossing_pairs(batch, motion, i)
    layer = min_layers(n_beams, np.concatenate([crossings, joints]), merged)
    return LayerPlan(layer, int(layer.max()) + 1, crossings, joints, merged)
