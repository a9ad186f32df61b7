"""Rigid-body invariants of every simulated linkage, in the kernel and in the reference.

docs/simulator.md: beam lengths are exact except for triangles solved inside
circle_intersection's tolerance band, where step 5 divides by the nudged distance d' and
both beams of the triangle scale by the same factor d / d' (stretched by less than ~t
outside the band's outer edge, shrunk by d / (d + t) inside its inner edge). Legacy mode
adds two more cases: step 4 (|d - l1 + l2| < t) puts the node on the line A -> C at
l1 * d / d' from A, and coincident anchors with equal radii put it at l1 from the origin.
"""

from __future__ import annotations

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.linkage import reference
from linkevo.sim.linkage.genome import MAX_BEAMS, N_NODES

T = reference.TOLERANCE
EXACT = 1e-9


def _gather(positions: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """Returns positions (N, 12, A, 2) of one node per linkage `nodes` (N,) as (N, A, 2)."""
    return positions[np.arange(len(nodes)), nodes]


def _norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1])


def check_invariants(
    positions: np.ndarray,
    valid: np.ndarray,
    beam_start: np.ndarray,
    beam_end: np.ndarray,
    beam_length: np.ndarray,
    mode: str,
) -> dict[str, int]:
    """Asserts the rigid-body invariants; returns how many samples fell in each case.

    Args:
        positions: (N, 12, A, 2), NaN at failed angles.
        valid: (N, A).
        beam_start, beam_end: (N, 15) int, -1 where absent.
        beam_length: (N, 15).
        mode: "paper" or "legacy".
    """
    assert valid[:, 0].all(), "angle 0 never fails"
    assert np.isnan(positions[~valid[:, None, :].repeat(N_NODES, 1)]).all()
    assert np.isfinite(positions[valid[:, None, :].repeat(N_NODES, 1)]).all()
    moving_mask = valid[:, None, :, None]
    for node in range(4):
        still = positions[:, node] - positions[:, node, :1]
        assert np.all(np.where(moving_mask[:, 0], still, 0.0) == 0.0), "a static node moved"
    assert (beam_start[:, 0] == 0).all() and (beam_end[:, 0] == 4).all()
    crank = _norm(positions[:, 4] - positions[:, 0])
    np.testing.assert_allclose(
        crank[valid], np.broadcast_to(beam_length[:, :1], crank.shape)[valid], atol=EXACT
    )
    counts = dict.fromkeys(("exact", "outer band", "inner band", "tangent", "coincident"), 0)
    rows = np.arange(len(valid))
    for node in range(5, N_NODES):
        into = beam_end == node
        n_into = into.sum(axis=1)
        assert np.isin(n_into, (1, 2)).all()
        first = into.argmax(axis=1)
        second = np.minimum(first + 1, MAX_BEAMS - 1)
        x = positions[:, node]
        a = _gather(positions, beam_start[rows, first])
        la = _norm(x - a)
        r0 = beam_length[rows, first][:, None]
        ext = (n_into == 1)[:, None] & valid
        np.testing.assert_allclose(la[ext], np.broadcast_to(r0, la.shape)[ext], atol=EXACT)
        c = _gather(positions, beam_start[rows, second])
        lc = _norm(x - c)
        r1 = beam_length[rows, second][:, None]
        tri = (n_into == 2)[:, None] & valid
        d = _norm(c - a)
        r0, r1 = np.broadcast_to(r0, d.shape), np.broadcast_to(r1, d.shape)
        tangent = tri & (mode == "legacy") & (np.abs(d - r0 + r1) < T)
        coincident = tri & (mode == "legacy") & (d == 0) & (r0 == r1)
        outer = tri & ~tangent & ~coincident & (d > r0 + r1)
        inner = tri & ~tangent & ~coincident & (d < np.abs(r0 - r1))
        exact = tri & ~tangent & ~coincident & ~outer & ~inner
        for case, mask in zip(
            ("exact", "outer band", "inner band", "tangent", "coincident"),
            (exact, outer, inner, tangent, coincident),
            strict=True,
        ):
            counts[case] += int(mask.sum())
        assert np.abs(la - r0)[exact].max(initial=0) < EXACT
        assert np.abs(lc - r1)[exact].max(initial=0) < EXACT
        nudged = np.where(d > r0 + r1, d - T, np.where(d < np.abs(r0 - r1), d + T, d))
        scale = d / np.where(nudged == 0, 1.0, nudged)
        # Step 5 scales both beams by d / d' where the nudged circles meet; where they miss
        # (possible when min(l1, l2) < t / 2), h = 0 and the node lies on the line A -> C.
        meet = (nudged >= np.abs(r0 - r1) + EXACT) & (nudged <= r0 + r1 - EXACT)
        miss = (nudged < np.abs(r0 - r1) - EXACT) | (nudged > r0 + r1 + EXACT)
        for mask in (outer & meet, inner & meet):
            np.testing.assert_allclose(la[mask], (r0 * scale)[mask], atol=EXACT)
            np.testing.assert_allclose(lc[mask], (r1 * scale)[mask], atol=EXACT)
        # Outside the outer edge the stretch stays below ~t: with l1 >= 2 it is at most
        # l1 * t / (d - t) plus, where the nudged circles miss, a few thousandths.
        assert (np.maximum(la - r0, lc - r1)[outer] < 1.1 * T).all()
        # Where the nudged circles miss (h = 0), and in legacy step 4, the node lies on the
        # line A -> C.
        u, v = c - a, x - a
        cross = np.abs(u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0])
        assert cross[tangent | ((outer | inner) & miss)].max(initial=0) < 1e-7
        np.testing.assert_allclose(la[tangent], (r0 * scale)[tangent], atol=EXACT)
        np.testing.assert_allclose(_norm(x)[coincident], r0[coincident], atol=EXACT)
    return counts


@pytest.fixture(scope="module", params=sim.MODES)
def kernel_run(request):
    mode = request.param
    genomes = np.random.default_rng(10_000).random((10_000, sim.N_GENES))
    batch = sim.decode(genomes, mode)
    return mode, batch, sim.simulate(batch)


def test_kernel_keeps_beams_rigid_on_10000_random_genomes(kernel_run):
    mode, batch, motion = kernel_run
    counts = check_invariants(
        motion.positions,
        motion.valid,
        batch.beam_start,
        batch.beam_end,
        batch.beam_length,
        mode,
    )
    assert counts["exact"] > 1_000_000
    assert counts["outer band"] > 0 and counts["inner band"] > 0  # the band was exercised
    if mode == "legacy":
        assert counts["tangent"] > 0


def test_kernel_keeps_beams_rigid_on_heavily_mutated_genomes(mutated_set):
    for mode in sim.MODES:
        batch = sim.decode(mutated_set, mode)
        motion = sim.simulate(batch)
        counts = check_invariants(
            motion.positions,
            motion.valid,
            batch.beam_start,
            batch.beam_end,
            batch.beam_length,
            mode,
        )
        assert counts["exact"] > 50_000
        assert counts["outer band"] + counts["inner band"] > 0


def reference_arrays(genomes: np.ndarray, mode: str) -> tuple[np.ndarray, ...]:
    """Returns the reference's (positions, valid, beam_start, beam_end, beam_length)."""
    n = len(genomes)
    beam_start = np.full((n, MAX_BEAMS), -1)
    beam_end = np.full((n, MAX_BEAMS), -1)
    beam_length = np.zeros((n, MAX_BEAMS))
    positions, valid = [], []
    for i, genome in enumerate(genomes):
        linkage = reference.decode_linkage(genome, mode)
        motion = reference.simulate_linkage(linkage)
        for b, beam in enumerate(linkage.beams):
            beam_start[i, b], beam_end[i, b], beam_length[i, b] = beam.start, beam.end, beam.length
        positions.append(motion.positions)
        valid.append(motion.valid)
    return np.array(positions), np.array(valid), beam_start, beam_end, beam_length


@pytest.mark.parametrize("mode", sim.MODES)
def test_reference_keeps_beams_rigid(mode, random_set, mutated_set):
    genomes = np.concatenate([random_set[:300], mutated_set[:300]])
    counts = check_invariants(*reference_arrays(genomes, mode), mode)
    assert counts["exact"] > 20_000 and counts["outer band"] + counts["inner band"] > 0
