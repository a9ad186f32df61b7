"""Paper and legacy modes differ exactly where the spec marks [legacy], and nowhere else.

The five differences: extension length, circle_intersection step 4, the backup-angle
origin, the accumulated crank angle and F_ae. Each test isolates one of them.
"""

from __future__ import annotations

import math

import numpy as np

from linkevo import sim
from linkevo.sim.linkage import reference
from linkevo.sim.linkage.genome import BLOCK_SIZE, FIRST_BLOCK, N_BLOCKS

T = reference.TOLERANCE


def both_modes(genome: np.ndarray, n_angles: int = 40):
    """Returns {mode: (reference linkage, reference motion, kernel motion)}."""
    out = {}
    for mode in sim.MODES:
        linkage = reference.decode_linkage(genome, mode)
        kernel = sim.simulate(sim.decode(genome[None], mode), n_angles)
        out[mode] = (linkage, reference.simulate_linkage(linkage, n_angles), kernel)
    return out


def test_extension_length_reads_its_own_gene_in_paper_and_the_crank_gene_in_legacy(builder):
    b = builder(crank=3.5)
    node = b.extension(0, 9.0)  # continues the crank beyond its tip
    genome = b.genome()
    runs = both_modes(genome)
    assert runs["paper"][0].blocks[0].length == 9.0
    assert runs["legacy"][0].blocks[0].length == 12.0 * genome[6] + 3.0 == 6.0
    for mode, length in (("paper", 9.0), ("legacy", 6.0)):
        _, motion, kernel = runs[mode]
        radius = np.hypot(*motion.positions[node].T)
        np.testing.assert_allclose(radius, 3.5 + length, atol=1e-9)
        np.testing.assert_allclose(kernel.positions[0, node], motion.positions[node], atol=1e-9)
    # Setting the paper length to the legacy one makes the two modes agree.
    genome[FIRST_BLOCK + 6] = (6.0 - 2.0) / 13.0
    runs = both_modes(genome)
    np.testing.assert_allclose(
        runs["paper"][1].positions[node], runs["legacy"][1].positions[node], atol=1e-12
    )


def test_legacy_step_4_snaps_near_tangent_triangles_onto_the_anchor_line(builder):
    # Triangle anchored at static S = (-4, 0) (l1 = 6.15) and the crank tip (l2 = 2): the
    # anchor distance d sweeps [2, 6] and passes the inner tangency d = l1 - l2 = 4.15,
    # within t of it at k = 11 and 29 (d = 4.183).
    l1, l2 = 6.15, 2.0
    gap = l1 - l2
    b = builder(statics=((-4, 0), (-5, 5), (5, 5)), crank=2.0)
    node = b.triangle(1, 4, l1, l2, direction=1)
    runs = both_modes(b.genome())
    s = np.array([-4.0, 0.0])
    _, legacy, legacy_kernel = runs["legacy"]
    _, paper, paper_kernel = runs["paper"]
    np.testing.assert_array_equal(legacy.valid, paper.valid)
    tip = paper.positions[4]
    d = np.linalg.norm(tip - s, axis=1)
    near = (np.abs(d - gap) < T) & paper.valid
    assert near.sum() >= 2
    expected = s + l1 * (tip[near] - s) / d[near][:, None]  # d inside the range: no nudge
    np.testing.assert_allclose(legacy.positions[node, near], expected, atol=1e-9)
    np.testing.assert_allclose(legacy_kernel.positions[0, node, near], expected, atol=1e-9)
    # Paper mode solves the true intersection there: both beam lengths hold.
    for anchor, length in ((s, l1), (tip[near], l2)):
        np.testing.assert_allclose(
            np.linalg.norm(paper.positions[node, near] - anchor, axis=1), length, atol=1e-9
        )
    assert np.abs(paper.positions[node, near] - legacy.positions[node, near]).min() > 0.1
    # Away from tangency both modes place the node identically.
    far = ~near & paper.valid
    assert far.sum() >= 10
    np.testing.assert_allclose(
        legacy.positions[node, far], paper.positions[node, far], rtol=0, atol=1e-9
    )
    np.testing.assert_allclose(paper_kernel.positions[0, node], paper.positions[node], atol=1e-9)


def test_backup_angle_is_measured_from_anchor_a_in_paper_and_from_the_origin_in_legacy(builder):
    # Every robot connection and the crank tip (length 2, angle 0) sit at (2, 0): the repair
    # of C runs out of candidates and keeps C = 2, coincident with A = 1, and l2 = l1.
    b = builder(statics=((2, 0), (2, 0), (2, 0)), crank=2.0)
    backup = 2.0
    node = b.triangle(1, 2, 5.0, 5.0, backup_angle=backup)
    runs = both_modes(b.genome())
    assert runs["paper"][0].blocks[0].l2 == runs["paper"][0].blocks[0].l1 == 5.0
    offset = 5.0 * np.array([math.cos(backup), math.sin(backup)])
    for mode, centre in (("paper", np.array([2.0, 0.0])), ("legacy", np.zeros(2))):
        _, motion, kernel = runs[mode]
        assert motion.valid.all()
        np.testing.assert_allclose(motion.positions[node], np.tile(centre + offset, (40, 1)))
        np.testing.assert_allclose(kernel.positions[0, node], motion.positions[node], atol=1e-9)


def test_legacy_accumulates_the_crank_angle(builder):
    genome = builder(crank=5.0).genome()
    step = 2.0 * math.pi / 40
    accumulated = [0.0]
    for _ in range(39):
        accumulated.append(accumulated[-1] + step)
    exact = [k * 2.0 * math.pi / 40 for k in range(40)]
    assert reference.crank_angles(40, "legacy") == accumulated
    assert reference.crank_angles(40, "paper") == exact
    assert accumulated != exact and np.allclose(accumulated, exact, rtol=0, atol=1e-13)
    for mode, thetas in (("legacy", accumulated), ("paper", exact)):
        tip = sim.simulate(sim.decode(genome[None], mode)).positions[0, 4]
        expected = [[5.0 * math.cos(t), 5.0 * math.sin(t)] for t in thetas]
        assert tip.tolist() == expected


def test_angle_error_counts_upward_samples_in_paper_and_weights_them_by_distance_in_legacy(
    builder,
):
    # No added node reaches below the crank tip, so the foot is the crank tip (node 4); the
    # crank is the one beam ending there and points upwards at angles k = 1..19.
    genome = builder(crank=3.0).genome()
    chord = 2.0 * 3.0 * math.sin(math.pi / 40)
    expected = {"paper": 19.0, "legacy": 19 * chord}
    for mode in sim.MODES:
        ev = sim.evaluate(genome[None], "Fp", mode)
        ref = reference.evaluate_reference(genome[None], "Fp", mode)
        assert ev.foot[0] == ref.foot[0] == 4
        assert math.isclose(ev.angle_error[0], expected[mode], abs_tol=1e-9)
        assert math.isclose(ref.angle_error[0], expected[mode], abs_tol=1e-9)
    paper = sim.evaluate(genome[None], "Fp", "paper")
    legacy = sim.evaluate(genome[None], "Fp", "legacy")
    np.testing.assert_allclose(
        paper.loss - paper.angle_error, legacy.loss - legacy.angle_error, atol=1e-9
    )


def test_modes_agree_without_extensions_tangency_or_coincident_anchors(random_set):
    genomes = random_set[:300].copy()
    for i in range(N_BLOCKS):
        type_gene = FIRST_BLOCK + BLOCK_SIZE * i
        genomes[:, type_gene] = 0.25 + 0.75 * genomes[:, type_gene]  # all triangles
    clean = []
    for genome in genomes:
        near_tangent = False
        for mode in sim.MODES:  # a sample may assemble in one mode only
            linkage = reference.decode_linkage(genome, mode)
            motion = reference.simulate_linkage(linkage)
            for block in linkage.blocks:
                a = motion.positions[block.anchor_a, motion.valid]
                c = motion.positions[block.anchor_c, motion.valid]
                d = np.linalg.norm(c - a, axis=1)
                near_tangent |= bool((np.abs(d - block.l1 + block.l2) < T + 1e-6).any())
                near_tangent |= bool((d == 0).any())
        clean.append(not near_tangent)
    clean = np.array(clean)
    assert clean.sum() > 150
    paper = sim.evaluate(genomes[clean], "Fp", "paper")
    legacy = sim.evaluate(genomes[clean], "Fp", "legacy")
    for field in ("error", "valid", "foot"):
        np.testing.assert_array_equal(getattr(paper, field), getattr(legacy, field))
    for field in ("foot_x", "foot_y"):
        np.testing.assert_allclose(getattr(paper, field), getattr(legacy, field), atol=1e-9)
    # Only F_ae differs: paper counts upward samples, legacy weights them by distance.
    np.testing.assert_allclose(
        paper.loss - paper.angle_error, legacy.loss - legacy.angle_error, atol=1e-9
    )
    assert (paper.angle_error != legacy.angle_error).any()
    for name in paper.descriptors:
        np.testing.assert_allclose(paper.descriptors[name], legacy.descriptors[name], atol=1e-9)
