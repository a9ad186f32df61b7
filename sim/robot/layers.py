"""Provides the layer plan of a built linkage: beams that cross during the turn go on
different layers, with as few layers as possible.

Two beams conflict when, at any sampled crank angle, their segments cross (a proper
intersection: each segment's ends on opposite sides of the other's line), or when they
meet at a joint: a pin joins beams stacked on different layers. An extension and the beam
it continues are one straight beam (the sheet says so), so they share a layer instead.
The fewest layers is the chromatic number of the conflict graph, found exactly by a
depth-first search over at most 15 beams, and of the plans with that many layers the plan
is the lexicographically first in beam order (the beams nearest the crank nearest the
frame). A mixed-integer programme (`scipy.optimize.milp`) finds the same number, but any
optimal plan the solver happens to return, and takes tens of milliseconds where the
search takes microseconds: the layer plan is part of every leg a walk builds.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from linkevo.sim.linkage.decoding import LinkageBatch
from linkevo.sim.linkage.kinematics import Motion

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
    pair (K, 2) shares one and every `same` pair (M, 2) does: of the colourings with the
    fewest layers, the first in item order (`_colouring`)."""
    conflicts = np.asarray(conflicts, dtype=np.int64).reshape(-1, 2)
    same = np.zeros((0, 2), np.int64) if same is None else np.asarray(same, np.int64).reshape(-1, 2)
    key = (n_items, tuple(map(tuple, conflicts.tolist())), tuple(map(tuple, same.tolist())))
    return np.array(_colouring(*key), dtype=np.int64)


@functools.lru_cache(maxsize=4096)
def _colouring(
    n_items: int, conflicts: tuple[tuple[int, int], ...], same: tuple[tuple[int, int], ...]
) -> tuple[int, ...]:
    """`min_layers` on a hashable graph: the layer of each item.

    Items joined by `same` are one group. For k = 1, 2, ... layers, the groups are given
    layers in item order by a depth-first search that tries the lowest layer first and
    never opens layer l + 1 before layer l: the first colouring it completes is the
    lexicographically first with k layers, so the plan is the same whoever computes it.
    """
    group = list(range(n_items))

    def root(i: int) -> int:
        while group[i] != i:
            i = group[i]
        return i

    for a, b in same:
        group[root(a)] = root(b)
    roots = sorted(
        {root(i) for i in range(n_items)},
        key=lambda r: min(i for i in range(n_items) if root(i) == r),
    )
    index = {r: g for g, r in enumerate(roots)}
    neighbours: list[set[int]] = [set() for _ in roots]
    for a, b in conflicts:
        ga, gb = index[root(a)], index[root(b)]
        if ga == gb:
            raise ValueError(f"no layer plan: a merged pair also conflicts (items {a}, {b})")
        neighbours[ga].add(gb)
        neighbours[gb].add(ga)
    colour = [-1] * len(roots)

    def place(g: int, k: int, opened: int) -> bool:
        if g == len(roots):
            return True
        taken = {colour[h] for h in neighbours[g] if h < g}
        for layer in range(min(k, opened + 1)):
            if layer not in taken:
                colour[g] = layer
                if place(g + 1, k, max(opened, layer + 1)):
                    return True
        colour[g] = -1
        return False

    for k in range(1, len(roots) + 1):
        if place(0, k, 0):
            break
    return tuple(colour[index[root(i)]] for i in range(n_items))


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
