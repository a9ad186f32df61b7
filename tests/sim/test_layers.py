"""Tests the layer plan: the fewest layers (exact on graphs with a known answer, and against
a brute-force search with pins in the way), no two beams on one layer within a beam's width
(checked by dense sampling, independent of the plan), bars wider than a beam, and beams kept
off the frame's axles."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.robot.layers import (
    CLEARANCE_MODULES,
    LONGEST_PIN,
    LayerError,
    Passes,
    crossing_pairs,
    layer_plan,
    min_layers,
    passes_of,
)

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


def segment_gap(p1, p2, p3, p4) -> float:
    """The least distance between two segments over the sampled angles ((A, 2) ends each),
    the segments sampled densely (independent of the plan)."""
    t = np.linspace(0.0, 1.0, 61)[None, :, None]
    a = p1[:, None] + t * (p2 - p1)[:, None]  # (A, 61, 2)
    b = p3[:, None] + t * (p4 - p3)[:, None]
    return float(np.linalg.norm(a[:, :, None] - b[:, None], axis=-1).min())


def test_no_two_beams_on_one_layer_come_within_a_beams_width():
    genomes = sim.random_genomes(np.random.default_rng(9), 1500)
    batch = sim.decode(genomes)
    motion = sim.simulate(batch, 24)
    checked = 0
    for i in np.flatnonzero(motion.error == 0)[:16]:
        plan = layer_plan(batch, motion, int(i), fastened=False)
        n_beams = int(batch.n_beams[i])
        ends = batch.beam_int[i, :n_beams, :2]
        pos = motion.positions[i]
        group = list(range(n_beams))  # a beam and its extensions: one straight beam
        for b in range(n_beams):
            parent = batch.beam_int[i, b, 3]
            if parent >= 0:
                group[b] = group[parent]
        near = set()
        for a, b in itertools.combinations(range(n_beams), 2):
            if set(ends[a]) & set(ends[b]):  # they meet at a joint
                if group[a] == group[b]:
                    assert plan.layer[a] == plan.layer[b]
                else:  # a pin joins stacked beams
                    assert plan.layer[a] != plan.layer[b]
                continue
            (s1, e1), (s2, e2) = ends[a], ends[b]
            gap = segment_gap(pos[s1], pos[e1], pos[s2], pos[e2])
            if gap < CLEARANCE_MODULES - 0.02 and group[a] != group[b]:
                near.add((a, b))
                assert plan.layer[a] != plan.layer[b], (i, a, b)
        found = {tuple(p) for p in crossing_pairs(batch, motion, int(i)).tolist()}
        assert near <= found and all(group[a] != group[b] or (a, b) not in near for a, b in found)
        checked += bool(near)
    assert checked > 5  # most of them have beams that would rub


def test_a_bar_longer_than_the_longest_beam_takes_two_layers():
    got = min_layers(3, np.array([[0, 1], [1, 2]]), width=np.array([1, 2, 1]))
    assert list(got) == [0, 1, 0]  # item 1 takes layers 1 and 2
    got = min_layers(3, np.array([[0, 1], [1, 2], [0, 2]]), width=np.array([2, 1, 1]))
    assert sorted([(got[0], 2), (got[1], 1), (got[2], 1)]) == [(0, 2), (2, 1), (3, 1)]


def brute_force(n, conflicts, passes: Passes, top: int = 6):
    """The fewest layers honouring conflicts and passes, by trying every assignment."""
    holders = {}
    for item, node in passes.holds:
        holders.setdefault(node, set()).add(item)
    for k in range(1, top + 1):
        for layers in itertools.product(range(k), repeat=n):
            if any(layers[a] == layers[b] for a, b in conflicts):
                continue
            ok = True
            for item, node in passes.passes:
                held = holders.get(node, set())
                if not held or item in held:  # a beam does not pass its own joint
                    continue
                low, high = min(layers[h] for h in held), max(layers[h] for h in held)
                if node in passes.frame:
                    ok &= layers[item] > high + 1
                elif node == passes.motor:
                    ok &= layers[item] > high
                elif len(held) >= 2:  # past a pin, or an axle's half bushes
                    bush = high - low + 1 > LONGEST_PIN
                    ok &= layers[item] < low - bush or layers[item] > high + bush
            if ok:
                return k
    return None


def test_a_beam_passing_a_pin_keeps_off_its_layers_as_few_layers_as_possible():
    rng = np.random.default_rng(4)
    for _ in range(25):
        n = int(rng.integers(3, 7))
        conflicts = [p for p in itertools.combinations(range(n), 2) if rng.random() < 0.3]
        nodes = list(range(4))
        holds = tuple(sorted({(int(rng.integers(n)), node) for node in nodes for _ in range(3)}))
        passes = tuple((int(rng.integers(n)), int(rng.choice(nodes))) for _ in range(3))
        for node in nodes:  # a joint's beams are stacked: they conflict, as the plan has them
            held = sorted({h for h, m in holds if m == node})
            conflicts += [p for p in itertools.combinations(held, 2) if p not in conflicts]
        spec = Passes(holds, passes, frame=(1,), motor=0)
        want = brute_force(n, conflicts, spec)
        if want is None:
            with pytest.raises(LayerError):
                min_layers(n, np.array(conflicts, np.int64).reshape(-1, 2), passes=spec)
            continue
        got = min_layers(n, np.array(conflicts, np.int64).reshape(-1, 2), passes=spec)
        assert got.max() + 1 == want, (conflicts, spec)
        assert brute_force(n, conflicts, spec) == want
        for item, node in passes:
            held = {h for h, m in holds if m == node}
            if held and node == 1 and item not in held:
                assert got[item] > max(got[h] for h in held) + 1


def test_a_fastened_plan_keeps_every_beam_off_the_frames_axles():
    genomes = sim.random_genomes(np.random.default_rng(11), 400)
    batch = sim.decode(genomes)
    motion = sim.simulate(batch, 24)
    planned = 0
    for i in np.flatnonzero(motion.error == 0)[:40]:
        try:
            plan = layer_plan(batch, motion, int(i))
        except LayerError:
            continue
        planned += 1
        spec = passes_of(batch, motion, int(i))
        for item, node in spec.passes:
            held = [h for h, m in spec.holds if m == node and h != item]
            if node in spec.frame and held:
                assert plan.layer[item] > max(plan.layer[h] + plan.width[h] - 1 for h in held) + 1
    assert planned >= 5
