"""Provides the layer plan of a built linkage: beams that would meet during the turn go on
different layers, with as few layers as possible.

Two beams conflict when, at any sampled crank angle, their centre lines cross or come
closer than a beam's width plus a little clearance (`CLEARANCE_MODULES`: two thick beams
side by side on one layer would rub), or when they meet at a joint: a pin joins beams
stacked on different layers. An extension and the beam it continues are one straight bar
(built as one Technic beam, `sim.robot.parts`), so they share a layer; a bar longer than
the longest Technic beam is built as two beams joined side by side and takes two layers
(`WIDE_SPAN`). A beam that comes near a node where it has no hole (`PASS_MODULES`) passes
that node's pin or axle, so it keeps off the layers the fastener takes (`Passes`): further
out than a frame pivot's axle and its half bush, or the motor's axle; wholly below or above
a moving joint's beams, a layer further where the joint spans more than a pin's three
layers and is an axle with half bushes.

The fewest layers is found exactly by a depth-first search over at most 15 bars, and of the
plans with that many layers the plan is the lexicographically first in beam order (the
beams nearest the crank nearest the frame): microseconds, and the layer plan is part of
every leg a walk builds. Where that plan puts a beam on a fastener's layers, the fewest
layers honouring the passes as well are a mixed-integer programme (`scipy.optimize.milp`,
milliseconds).
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass

import numpy as np

from linkevo.sim.errors import LinkevoError
from linkevo.sim.linkage.decoding import NODE_KINDS, LinkageBatch
from linkevo.sim.linkage.kinematics import Motion

COLLINEAR = 1e-9
"""A cross product (square modules) below this is taken as zero: the points are collinear."""
CLEARANCE_MODULES = 1.0
"""Beams of one layer whose centre lines come closer than this (a thick beam's 7.2 mm width
and 0.8 mm of clearance) would rub: they go on different layers."""
WIDE_SPAN = 15
"""A bar spanning this many modules or more between its end holes needs more than the
longest Technic beam (15 holes, 14 modules): it is built as beams joined side by side on
two layers."""


@dataclass(frozen=True)
class LayerPlan:
    """The layers of one linkage's beams.

    Attributes:
        layer: (B,) int64 layer of each beam, 0 nearest the frame.
        n_layers: how many layers are used.
        crossings: (K, 2) int64 the beam pairs that cross at some sampled angle.
        joints: (J, 2) int64 the beam pairs that meet at a joint (on different layers).
        merged: (M, 2) int64 (extension, parent) pairs built as one beam (one layer).
        width: (B,) int64 the layers each beam's bar takes from its `layer` on: 2 for a
            bar of `WIDE_SPAN` modules or more (two beams joined), else 1.
    """

    layer: np.ndarray
    n_layers: int
    crossings: np.ndarray
    joints: np.ndarray
    merged: np.ndarray
    width: np.ndarray


def crossing_pairs(batch: LinkageBatch, motion: Motion, i: int = 0) -> np.ndarray:
    """Returns (K, 2) the pairs of linkage i's beams, sharing no node, that cross or come
    closer than `CLEARANCE_MODULES` at an assembled angle.

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
    near = segment_distance(p[a], q[a], p[b], q[b]) < CLEARANCE_MODULES  # (K, A')
    hit = near.any(axis=1)
    return np.stack([a[hit], b[hit]], axis=1).astype(np.int64)


def segment_distance(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Returns the least distance between segments p1-q1 and p2-q2 ((..., 2) ends each,
    broadcast): 0 where they cross (each one's ends on opposite sides of the other's line,
    collinear within `COLLINEAR` not counted as crossing), else the least distance from an
    end of one to the other."""

    def side(o, d, x):
        value = (d[..., 0] - o[..., 0]) * (x[..., 1] - o[..., 1]) - (d[..., 1] - o[..., 1]) * (
            x[..., 0] - o[..., 0]
        )
        return np.where(np.abs(value) < COLLINEAR, 0.0, np.sign(value))

    def to_segment(x, o, d):
        along = d - o
        t = np.einsum("...i,...i->...", x - o, along)
        t = np.clip(t / np.maximum(np.einsum("...i,...i->...", along, along), 1e-12), 0.0, 1.0)
        return np.linalg.norm(x - o - t[..., None] * along, axis=-1)

    cross = (side(p1, q1, p2) * side(p1, q1, q2) < 0) & (side(p2, q2, p1) * side(p2, q2, q1) < 0)
    ends = np.minimum(
        np.minimum(to_segment(p1, p2, q2), to_segment(q1, p2, q2)),
        np.minimum(to_segment(p2, p1, q1), to_segment(q2, p1, q1)),
    )
    return np.where(cross, 0.0, ends)


class LayerError(LinkevoError, ValueError):
    """No layer plan within `MAX_LAYERS` keeps every pin clear; says why."""


MAX_LAYERS = 14
"""The most layers a plan may use (a 16-module axle, the longest, spans them with the
frame's grip and the driver's layer)."""
LONGEST_PIN = 3
"""The most layers a Technic pin joins; a moving joint across more is an axle held by a
half bush past each end beam, so an item passing it keeps a layer clear of them."""


@dataclass(frozen=True)
class Passes:
    """Where fasteners stand in the way (hashable, for `min_layers`).

    Attributes:
        holds: (item, node) pairs: the item has a hole at the node.
        passes: (item, node) pairs: the item comes near the node over the turn without a
            hole there.
        frame: the static nodes: the frame's axle there takes every layer from the frame up
            to one past its highest item (the half bush that holds them on), so an item
            passing it must lie further out.
        motor: the motor's node: its axle takes every layer from the frame up to the crank
            (held on by the driver's pin, no bush), so an item passing it lies further out.

    At any other node two items or more hold, the fastener takes their layers, lowest to
    highest; an item passing it must lie wholly below or wholly above them, and a layer
    further where the joint is an axle with half bushes (more than `LONGEST_PIN` layers).
    """

    holds: tuple[tuple[int, int], ...] = ()
    passes: tuple[tuple[int, int], ...] = ()
    frame: tuple[int, ...] = ()
    motor: int = -1


def min_layers(
    n_items: int,
    conflicts: np.ndarray,
    same: np.ndarray | None = None,
    width: np.ndarray | None = None,
    passes: Passes | None = None,
) -> np.ndarray:
    """Returns (n_items,) int64 layers using the fewest layers such that no conflicting
    pair (K, 2) shares one, every `same` pair (M, 2) has one, and no item that passes a
    joint lies on a layer its fastener takes (`Passes`): item j takes the layers from its
    own to its own + width[j] - 1 (`width` (n_items,), 1 each by default).

    Without passes in the way the plan is the first in item order of the plans with the
    fewest layers (`_colouring`, a depth-first search: microseconds). Where that plan puts
    an item on a fastener's layers, the fewest layers honouring the passes too are found as
    a mixed-integer programme (`_programme`, `scipy.optimize.milp`; milliseconds).

    Raises:
        LayerError: when no plan within `MAX_LAYERS` layers exists.
    """
    conflicts = np.asarray(conflicts, dtype=np.int64).reshape(-1, 2)
    same = np.zeros((0, 2), np.int64) if same is None else np.asarray(same, np.int64).reshape(-1, 2)
    width = np.ones(n_items, np.int64) if width is None else np.asarray(width, np.int64)
    passes = passes or Passes()
    key = (
        n_items,
        tuple(map(tuple, conflicts.tolist())),
        tuple(map(tuple, same.tolist())),
        tuple(width.tolist()),
    )
    found = _colouring(*key)
    if _in_the_way(found, width, passes):
        fewest = max(layer + w for layer, w in zip(found, width, strict=True))
        found = _programme(*key, passes, fewest)
    if found is None:
        raise LayerError(
            f"no plan of at most {MAX_LAYERS} layers keeps every beam off the pins and axles "
            f"it passes over the turn{_why(passes)}"
        )
    return np.array(found, dtype=np.int64)


def _why(passes: Passes) -> str:
    """A pair of beams each of which must lie further out than the other (each passes the
    frame's or the motor's axle through the other's hole), in words; "" when none."""
    holders: dict[int, set[int]] = {}
    for item, node in passes.holds:
        holders.setdefault(node, set()).add(item)
    outside = {}  # (passer, holder) -> node: the passer must lie further out
    for item, node in passes.passes:
        if node in passes.frame or node == passes.motor:
            for h in holders.get(node, set()) - {item}:
                outside[(item, h)] = node
    for (a, b), node in sorted(outside.items()):
        if (b, a) in outside:
            return (
                f": beam b{a} passes the axle at node {node} through beam b{b}, and b{b} the "
                f"axle at node {outside[(b, a)]} through b{a} (each must lie further out than "
                "the other)"
            )
    return ""


def _groups(n_items: int, same) -> tuple[list[int], list[int]]:
    """Returns (each item's group, the groups' first items): items joined by `same` are
    one group, numbered by their first item."""
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
    return [index[root(i)] for i in range(n_items)], [
        min(i for i in range(n_items) if root(i) == r) for r in roots
    ]


def _holders(passes: Passes) -> dict[int, list[int]]:
    """Each node's items with a hole there."""
    holders: dict[int, list[int]] = {}
    for item, node in passes.holds:
        holders.setdefault(node, []).append(item)
    return holders


def _long_joints(layer, width, passes: Passes) -> set[int]:
    """The moving joints a plan makes longer than `LONGEST_PIN` layers (axles)."""
    out = set()
    for node, held in _holders(passes).items():
        if node in passes.frame or node == passes.motor:
            continue
        low, high = min(layer[h] for h in held), max(layer[h] + width[h] - 1 for h in held)
        if high - low + 1 > LONGEST_PIN:
            out.add(node)
    return out


def _in_the_way(layer, width, passes: Passes) -> bool:
    """Whether a plan (the layer of each item) puts a passing item on a fastener's layers
    (a moving joint's axle: on its half bushes' too)."""
    top = [layer[i] + width[i] - 1 for i in range(len(layer))]
    holders = _holders(passes)
    long = _long_joints(layer, width, passes)
    for item, node in passes.passes:
        held = holders.get(node, [])
        if item in held:  # an item does not pass its own joint
            continue
        if (node in passes.frame or node == passes.motor) and held:
            if layer[item] <= max(top[h] for h in held) + (node != passes.motor):
                return True
        elif len({layer[h] for h in held}) >= 2:
            bush = int(node in long)
            low, high = min(layer[h] for h in held) - bush, max(top[h] for h in held) + bush
            if not (top[item] < low or layer[item] > high):
                return True
    return False


@functools.lru_cache(maxsize=4096)
def _colouring(
    n_items: int,
    conflicts: tuple[tuple[int, int], ...],
    same: tuple[tuple[int, int], ...],
    width: tuple[int, ...],
) -> tuple[int, ...]:
    """The conflicts' plan: the layer of each item.

    For k = 1, 2, ... layers, the groups are given layers in item order by a depth-first
    search that tries the lowest layer first and never leaves a layer unused below the one
    it opens: the first plan it completes is the lexicographically first with k layers, so
    the plan is the same whoever computes it.
    """
    group, firsts = _groups(n_items, same)
    wide = [max(width[i] for i in range(n_items) if group[i] == g) for g in range(len(firsts))]
    neighbours: list[set[int]] = [set() for _ in firsts]
    for a, b in conflicts:
        if group[a] == group[b]:
            raise ValueError(f"no layer plan: a merged pair also conflicts (items {a}, {b})")
        neighbours[group[a]].add(group[b])
        neighbours[group[b]].add(group[a])
    colour = [-1] * len(firsts)

    def free(g: int, layer: int) -> bool:
        return all(
            layer + wide[g] <= colour[h] or colour[h] + wide[h] <= layer
            for h in neighbours[g]
            if h < g
        )

    def place(g: int, k: int, opened: int) -> bool:
        if g == len(firsts):
            return True
        for layer in range(min(k - wide[g], opened) + 1):
            if free(g, layer):
                colour[g] = layer
                if place(g + 1, k, max(opened, layer + wide[g])):
                    return True
        colour[g] = -1
        return False

    for k in range(max(wide), sum(wide) + 1):
        if place(0, k, 0):
            break
    return tuple(colour[group[i]] for i in range(n_items))


@functools.lru_cache(maxsize=4096)
def _programme(
    n_items: int,
    conflicts: tuple[tuple[int, int], ...],
    same: tuple[tuple[int, int], ...],
    width: tuple[int, ...],
    passes: Passes,
    fewest: int,
) -> tuple[int, ...] | None:
    """The plan honouring the passes as well, as a mixed-integer programme (None: none
    within `MAX_LAYERS`); `fewest` is the conflicts' plan's count, a bound from below.

    Variables: each group's layer y (its lowest), the layers used L, a binary per conflicting pair
    (which lies below), per pass at a moving joint (below or above its holders) and per moving joint
    passed (an axle with half bushes: its holders may span more than `LONGEST_PIN` layers, and a
    passer keeps a layer further off). A pass of a static node puts the passer above every holder
    (the frame's axle fills the layers below). Minimised: L (HiGHS, deterministic: the same plan
    wherever it runs).
    """
    from scipy.optimize import Bounds, LinearConstraint, milp

    group, firsts = _groups(n_items, same)
    n = len(firsts)
    wide = [max(width[i] for i in range(n_items) if group[i] == g) for g in range(n)]
    pairs = sorted({tuple(sorted((group[a], group[b]))) for a, b in conflicts})
    holders: dict[int, set[int]] = {}
    for item, node in passes.holds:
        holders.setdefault(node, set()).add(group[item])
    frame_rows, moving = [], []
    for item, node in sorted(set(passes.passes)):
        c, held = group[item], holders.get(node, set())
        if c in held or not held:
            continue
        if node in passes.frame:
            frame_rows += [(c, h, 1) for h in sorted(held)]
        elif node == passes.motor:
            frame_rows += [(c, h, 0) for h in sorted(held)]
        elif len(held) >= 2:
            moving.append((c, node, tuple(sorted(held))))
    moving = sorted(set(moving))
    axles = sorted({(node, held) for _, node, held in moving})  # a binary each: an axle?
    axle_of = {node: n + 1 + len(pairs) + len(moving) + k for k, (node, _) in enumerate(axles)}
    m = n + 1 + len(pairs) + len(moving) + len(axles)  # y, L, binaries: pairs, passes, axles
    big = MAX_LAYERS + 4
    rows, lower, upper = [], [], []

    def row(coefficients: dict[int, float], low: float, high: float) -> None:
        vector = np.zeros(m)
        for j, v in coefficients.items():
            vector[j] += v
        rows.append(vector)
        lower.append(low)
        upper.append(high)

    for g in range(n):  # y_g + w_g <= L
        row({g: 1.0, n: -1.0}, -np.inf, -wide[g])
    for k, (g, h) in enumerate(pairs):  # g below h, or h below g
        z = n + 1 + k
        row({g: 1.0, h: -1.0, z: -big}, -np.inf, -wide[g])
        row({h: 1.0, g: -1.0, z: big}, -np.inf, big - wide[h])
    for c, h, bush in frame_rows:  # beyond the frame's axle (and its half bush)
        row({c: 1.0, h: -1.0}, wide[h] + bush, np.inf)
    for node, held in axles:  # a joint across more than LONGEST_PIN layers is an axle
        for h, g in itertools.permutations(held, 2):
            row({g: 1.0, h: -1.0, axle_of[node]: -big}, -np.inf, LONGEST_PIN - wide[g])
    for k, (c, node, held) in enumerate(moving):  # wholly below every holder, or above
        b, a = n + 1 + len(pairs) + k, axle_of[node]  # (an axle's half bush: a layer more)
        for h in held:
            row({c: 1.0, h: -1.0, a: 1.0, b: -big}, -np.inf, -wide[c])
            row({c: 1.0, h: -1.0, a: -1.0, b: -big}, wide[h] - big, np.inf)
    weights = np.zeros(m)
    weights[n] = 1.0
    integrality = np.ones(m)
    low = np.zeros(m)
    low[n] = fewest
    high = np.concatenate([[MAX_LAYERS - w for w in wide], [MAX_LAYERS], np.ones(m - n - 1)])
    result = milp(
        weights,
        constraints=LinearConstraint(np.array(rows), lower, upper),
        integrality=integrality,
        bounds=Bounds(low, high),
    )
    if result.x is None:
        return None
    y = np.rint(result.x[:n]).astype(int)
    return tuple(int(y[group[i]]) for i in range(n_items))


def bar_of(batch: LinkageBatch, i: int = 0) -> np.ndarray:
    """Returns (B,) int64 each beam's bar: the first beam of the straight run it belongs to
    (a beam and every extension of it, built as one Technic beam or beams joined)."""
    n_beams = int(batch.n_beams[i])
    parent = batch.beam_int[i, :n_beams, 3]
    bar = np.arange(n_beams, dtype=np.int64)
    for b in range(n_beams):  # an extension follows its parent, decoded before it
        if parent[b] >= 0:
            bar[b] = bar[parent[b]]
    return bar


def bar_spans(batch: LinkageBatch, i: int = 0) -> np.ndarray:
    """Returns (B,) each beam's bar's span in modules: the beam and every extension of it
    (one straight bar), from its first hole to its last, measured along the bar at the
    linkage's build lengths (`LinkageBatch.beam_length`)."""
    n_beams = int(batch.n_beams[i])
    parent = batch.beam_int[i, :n_beams, 3]
    ends = batch.beam_int[i, :n_beams, :2]
    length = batch.beam_length[i, :n_beams]
    base = bar_of(batch, i)
    span = np.zeros(n_beams)
    for bar in np.unique(base):
        members = np.flatnonzero(base == bar)
        at = {int(ends[bar, 0]): 0.0, int(ends[bar, 1]): float(length[bar])}
        for b in members[1:]:  # an extension starts where its parent's end or start is
            s, e = int(ends[b, 0]), int(ends[b, 1])
            p = int(parent[b])
            ahead = at[int(ends[p, 1])] >= at[int(ends[p, 0])]
            step = float(length[b]) if (s == int(ends[p, 1])) == ahead else -float(length[b])
            at[e] = at[s] + step
        span[members] = max(at.values()) - min(at.values())
    return span


def layer_plan(batch: LinkageBatch, motion: Motion, i: int = 0, fastened: bool = True) -> LayerPlan:
    """Returns the layer plan of linkage i (the fewest layers with no two beams that would
    meet on one, no beam passing a pin or axle on a layer it takes, a bar of `WIDE_SPAN`
    modules or more taking two; `fastened` False: the pins and axles left out, for a
    linkage as evolved, which no real parts build).

    Raises:
        LayerError: when no plan within `MAX_LAYERS` exists.
    """
    n_beams = int(batch.n_beams[i])
    ends = batch.beam_int[i, :n_beams, :2]
    parent = batch.beam_int[i, :n_beams, 3]
    merged = np.array([(b, parent[b]) for b in range(n_beams) if parent[b] >= 0], np.int64)
    merged = merged.reshape(-1, 2)
    group = bar_of(batch, i)
    a, b = np.triu_indices(n_beams, k=1)
    meet = [
        bool(set(ends[x]) & set(ends[y])) and group[x] != group[y]
        for x, y in zip(a, b, strict=True)
    ]
    joints = np.stack([a[meet], b[meet]], axis=1).astype(np.int64)
    crossings = crossing_pairs(batch, motion, i)
    crossings = crossings[group[crossings[:, 0]] != group[crossings[:, 1]]]
    width = np.where(bar_spans(batch, i) >= WIDE_SPAN - 1e-9, 2, 1).astype(np.int64)
    passes = passes_of(batch, motion, i) if fastened else None
    layer = min_layers(n_beams, np.concatenate([crossings, joints]), merged, width, passes)
    return LayerPlan(layer, int((layer + width).max()), crossings, joints, merged, width)


PASS_MODULES = 0.9
"""A beam whose centre line comes closer than this to a node (its half width and a
fastener's or filler's, 0.45 modules each) passes that node's fastener."""


def passes_of(batch: LinkageBatch, motion: Motion, i: int = 0) -> Passes:
    """Returns which of linkage i's beams hold and pass which nodes (`Passes`)."""
    n_beams = int(batch.n_beams[i])
    ends = batch.beam_int[i, :n_beams, :2]
    kinds = [NODE_KINDS[int(k)] for k in batch.node_int[i, :, 0]]
    pos = motion.positions[i][:, motion.valid[i]]  # (12, A', 2)
    nodes = np.unique(ends)
    holds = tuple((int(b), int(n)) for b in range(n_beams) for n in ends[b])
    d = segment_distance(
        pos[ends[:, 0]][:, None], pos[ends[:, 1]][:, None], pos[nodes][None], pos[nodes][None]
    )  # (B, N, A')
    near = (d < PASS_MODULES).any(axis=2)
    bar = bar_of(batch, i)  # a bar has one hole at each node of its beams
    bar_nodes = {int(g): set(ends[bar == g].ravel().tolist()) for g in np.unique(bar)}
    passes = tuple(
        (int(b), int(nodes[k]))
        for b, k in zip(*np.nonzero(near), strict=True)
        if int(nodes[k]) not in bar_nodes[int(bar[b])]
    )
    frame = tuple(int(n) for n in nodes if kinds[n] == "static")
    return Passes(holds, passes, frame, kinds.index("motor"))
