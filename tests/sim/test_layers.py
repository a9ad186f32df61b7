"""Tests the layer plan: the fewest layers (exact on graphs with a known answer) and no
crossing on one layer (checked with a plain segment test, independent of the plan)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.robot.layers import crossing_pairs, layer_plan, min_layers

PETERSEN = [(i, (i + 1) % 5) for i in range(5)] + [(i, i + 5) for i in range(5)]
PETERSEN += [(5 + i, 5 + (i + 2) % 5) for i in range(5)]


@pytest.mark.parametrize(
    ("n", "edges", "layers"),
    [
        (1, [], 1),
        (4, [], 1),
        (4, [(0, 1), (2, 3)], 2),
        (4, [(0, 1), (1, 2), (2, 3), (3, 0)], 2),  # an even cycle
        (5, [(0, 1), (1, 2), (2, 3), (3, 4), (4, 0)], 3),  # an odd cycle
        (4, list(itertools.combinations(range(4), 2)), 4),  # K4
        (10, PETERSEN, 3),
        (15, [(i, j) for i in range(6) for j in range(6, 15)], 2),  # bipartite, 15 beams
    ],
)
def test_the_fewest_layers_on_known_graphs(n, edges, layers):
    got = min_layers(n, np.array(edges, dtype=np.int64))
    assert got.max() + 1 == layers
    assert all(got[a] != got[b] for a, b in edges)


def chromatic_number(n: int, edges: list[tuple[int, int]]) -> int:
    for k in range(1, n + 1):
        for colours in itertools.product(range(k), repeat=n):
            if all(colours[a] != colours[b] for a, b in edges):
                return k
    return n


def test_merged_items_share_a_layer():
    got = min_layers(3, np.array([[0, 2]]), np.array([[0, 1]]))
    assert got[0] == got[1] != got[2]
    with pytest.raises(ValueError, match="a merged pair also conflicts"):
        min_layers(2, np.array([[0, 1]]), np.array([[0, 1]]))


def test_the_fewest_layers_equal_a_brute_force_search():
    rng = np.random.default_rng(3)
    for _ in range(30):
        n = int(rng.integers(2, 8))
        pairs = list(itertools.combinations(range(n), 2))
        edges = [p for p in pairs if rng.random() < 0.5]
        got = min_layers(n, np.array(edges, dtype=np.int64).reshape(-1, 2))
        assert got.max() + 1 == chromatic_number(n, edges), edges


def segments_cross(p1, p2, p3, p4) -> bool:
    def orient(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    def sign(v: float) -> int:  # collinear within rounding: touching, not crossing
        return 0 if abs(v) < 1e-9 else (1 if v > 0 else -1)

    first = sign(orient(p1, p2, p3)) * sign(orient(p1, p2, p4))
    return first < 0 and sign(orient(p3, p4, p1)) * sign(orient(p3, p4, p2)) < 0


def test_no_two_beams_on_one_layer_cross_at_any_sampled_angle():
    genomes = sim.random_genomes(np.random.default_rng(9), 1500)
    batch = sim.decode(genomes)
    motion = sim.simulate(batch, 24)
    checked = 0
    for i in np.flatnonzero(motion.error == 0)[:40]:
        plan = layer_plan(batch, motion, int(i))
        n_beams = int(batch.n_beams[i])
        ends = batch.beam_int[i, :n_beams, :2]
        pos = motion.positions[i]
        crossing = set()
        group = list(range(n_beams))  # a beam and its extensions: one straight beam
        for b in range(n_beams):
            parent = batch.beam_int[i, b, 3]
            if parent >= 0:
                group[b] = group[parent]
        for a, b in itertools.combinations(range(n_beams), 2):
            if set(ends[a]) & set(ends[b]):  # they meet at a joint
                if group[a] == group[b]:
                    assert plan.layer[a] == plan.layer[b]
                else:  # a pin joins stacked beams
                    assert plan.layer[a] != plan.layer[b]
                continue
            (s1, e1), (s2, e2) = ends[a], ends[b]
            if any(
                segments_cross(pos[s1, k], pos[e1, k], pos[s2, k], pos[e2, k])
                for k in range(pos.shape[1])
            ):
                crossing.add((a, b))
                assert plan.layer[a] != plan.layer[b], (i, a, b)
        assert crossing == {tuple(p) for p in crossing_pairs(batch, motion, int(i)).tolist()}
        conflicts = np.concatenate([np.array(sorted(crossing)).reshape(-1, 2), plan.joints])
        assert plan.n_layers == min_layers(n_beams, conflicts, plan.merged).max() + 1
        checked += bool(crossing)
    assert checked > 10  # most of them have crossing beams
