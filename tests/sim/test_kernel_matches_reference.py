"""The fast kernel (`sim.linkage.decoding`, `sim.simulate`, `sim.linkage.evaluating`) equals the
plain reference.

Both implement the spec independently; they must agree to 1e-9 on every Evaluation field,
for all four fitnesses and both modes, on random genomes and on heavily mutated ones (many
genes near 0 and genes at exact bin edges, where ties and tangencies are common).
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.linkage import reference
from linkevo.sim.linkage.genome import MAX_BEAMS

ATOL = 1e-9
FIELDS = ("loss", "error", "angle_error", "valid", "foot", "foot_x", "foot_y")


def mismatched_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Returns the rows (first axis) where a and b differ by more than ATOL (NaN == NaN)."""
    assert a.shape == b.shape, (a.shape, b.shape)
    a = a.astype(np.float64).reshape(len(a), -1)
    b = b.astype(np.float64).reshape(len(b), -1)
    same = np.isclose(a, b, rtol=0.0, atol=ATOL, equal_nan=True)
    return np.flatnonzero(~same.all(axis=1))


def assert_same(name: str, kernel: np.ndarray, ref: np.ndarray, genomes: np.ndarray) -> None:
    """Asserts equality, naming the first bad row and its genome (a ready reproducer)."""
    rows = mismatched_rows(kernel, ref)
    if len(rows):
        row = rows[0]
        raise AssertionError(
            f"{name}: {len(rows)} rows differ, first row {row}: kernel {kernel[row]!r} vs "
            f"reference {ref[row]!r}; genome = {genomes[row].tolist()!r}"
        )


def assert_evaluations_equal(kernel, ref, genomes: np.ndarray) -> None:
    for field in FIELDS:
        assert getattr(kernel, field).dtype == getattr(ref, field).dtype, field
        assert_same(field, getattr(kernel, field), getattr(ref, field), genomes)
    assert set(kernel.descriptors) == set(ref.descriptors) == {"MAP-WH", "MAP-LIS", "MAP-ST"}
    for name, values in ref.descriptors.items():
        assert_same(name, kernel.descriptors[name], values, genomes)


@pytest.fixture(scope="module", params=["random", "mutated", "edges"])
def genomes(request, random_set, mutated_set, edge_set):
    return {"random": random_set, "mutated": mutated_set, "edges": edge_set}[request.param]


@pytest.mark.parametrize("mode", sim.MODES)
def test_evaluate_equals_reference_for_fp(genomes, mode):
    kernel = sim.evaluate(genomes, "Fp", mode)
    ref = reference.evaluate_reference(genomes, "Fp", mode)
    assert_evaluations_equal(kernel, ref, genomes)
    assert (ref.error == 0).sum() > 0 and (ref.error > 0).sum() > 0


@pytest.mark.parametrize("fitness", ["Fsl", "Fp2", "Fsl2"])
@pytest.mark.parametrize("mode", sim.MODES)
def test_evaluate_equals_reference_for_other_fitnesses(genomes, mode, fitness):
    subset = genomes[:200]
    kernel = sim.evaluate(subset, fitness, mode)
    ref = reference.evaluate_reference(subset, fitness, mode)
    assert ref.loss.shape == ((200, 2) if fitness.endswith("2") else (200,))
    assert_evaluations_equal(kernel, ref, subset)


@pytest.mark.parametrize("mode", sim.MODES)
def test_evaluate_equals_reference_for_d24_and_user_targets(random_set, mode):
    genomes = random_set[:150]
    user = sim.Target(points=np.array([[0.0, -1.0], [3.0, 2.0]]), is_step=np.array([1, 0]))
    for target in (sim.named_target("D24"), user):
        for fitness in ("Fp", "Fp2"):
            kernel = sim.evaluate(genomes, fitness, mode, target=target)
            ref = reference.evaluate_reference(genomes, fitness, mode, target=target)
            assert_same("loss", kernel.loss, ref.loss, genomes)


@pytest.mark.parametrize("n_angles", [3, 7, 64])
def test_evaluate_equals_reference_at_other_angle_counts(mutated_set, n_angles):
    genomes = mutated_set[:200]
    for mode in sim.MODES:
        kernel = sim.evaluate(genomes, "Fsl", mode, n_angles=n_angles)
        ref = reference.evaluate_reference(genomes, "Fsl", mode, n_angles=n_angles)
        assert kernel.valid.shape == (200, n_angles)
        assert_evaluations_equal(kernel, ref, genomes)


def test_fewer_angles_than_nodes_stay_inside_the_kernels_buffers():
    """Per-angle scratch once also held the 12 node positions at angle 0: with A < 12 the
    kernel wrote past it and corrupted the heap. Run where a crash cannot take pytest down."""
    code = (
        "import numpy as np, sim\n"
        "g = sim.random_genomes(np.random.default_rng(1), 5000)\n"
        "for _ in range(20):\n"
        "    ev = sim.evaluate(g, n_angles=4)\n"
        "assert np.isfinite(ev.loss).all()\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]


@pytest.mark.parametrize("mode", sim.MODES)
def test_decode_and_simulate_equal_reference(random_set, mutated_set, mode):
    genomes = np.concatenate([random_set[:200], mutated_set[:200]])
    batch = sim.decode(genomes, mode)
    motion = sim.simulate(batch)
    for i, genome in enumerate(genomes):
        linkage = reference.decode_linkage(genome, mode)
        ref = reference.simulate_linkage(linkage)
        n = len(linkage.beams)
        assert batch.n_beams[i] == n
        assert batch.beam_start[i, :n].tolist() == [b.start for b in linkage.beams]
        assert batch.beam_end[i, :n].tolist() == [b.end for b in linkage.beams]
        assert (batch.beam_start[i, n:] == -1).all() and (batch.beam_end[i, n:] == -1).all()
        lengths = np.array([b.length for b in linkage.beams])
        np.testing.assert_allclose(batch.beam_length[i, :n], lengths, rtol=0, atol=ATOL)
        np.testing.assert_allclose(batch.positions0[i], linkage.nodes, rtol=0, atol=ATOL)
        np.testing.assert_array_equal(motion.valid[i], ref.valid)
        np.testing.assert_allclose(motion.positions[i], ref.positions, rtol=0, atol=ATOL)
        np.testing.assert_allclose(
            motion.beam_angles[i, :n], ref.beam_angles, rtol=0, atol=ATOL, equal_nan=True
        )
        assert np.isnan(motion.beam_angles[i, n:MAX_BEAMS]).all()
        assert motion.foot[i] == ref.foot


# fmt: off
MIRRORED_FOOT = [
    0.5, 1 / 3, 1 / 3, 0.5, 0.00044731870389636507, 0.25, 0.0007733755964627727, 0.5,
    0.000455841043430822, 0.5 - 2**-54, 0.5 - 2**-54, 2 / 11, 0.25, 4.083582052122503e-05,
    0.5, 0.0, 1 / 11, 0.0, 0.0003738662350788684, 2 / 11, 1 / 11, 0.5, 0.5, 0.25,
    0.5 - 2**-54, 1 / 3, 1 / 3, 0.75, 1 / 11, 0.0, 2 / 11, 0.0, 0.00040232482396036995,
    0.0007703388962092794, 1 / 11, 0.25, 0.0006634535068395337, 2.581158323155719e-05,
    2 / 11, 0.00024487775646209496, 1 / 3, 0.5 - 2**-54, 0.0006953328223219034, 2 / 11,
    0.75, 1 / 11, 0.0009619657501647668, 2 / 11, 2 / 11, 0.5 - 2**-54,
    0.0005716387531323385, 0.5 - 2**-54, 0.00043283529613484474, 1 / 11, 1 / 11, 1 / 3,
]
# fmt: on
"""A bin-edge genome whose foot (node 9, a triangle) has its two beams mirrored about the
x-axis at crank angle k = 30: their recorded angles (in [0, 2 pi)) sum to exactly 2 pi, so
the mean is pi, not in (0, pi), and the sample is not counted, although dx_a*dy_c +
dx_c*dy_a = 5.3e-15 is a few ulps off zero."""


@pytest.mark.parametrize("mode", sim.MODES)
def test_angle_error_when_the_foot_beam_angles_cancel_exactly(mode):
    genome = np.array([MIRRORED_FOOT])
    linkage = reference.decode_linkage(genome[0], mode)
    motion = reference.simulate_linkage(linkage)
    assert motion.foot == 9 and motion.valid[30]
    into = [b for b, beam in enumerate(linkage.beams) if beam.end == 9]
    assert motion.beam_angles[into, 30].sum() == 2.0 * np.pi
    upward = (motion.foot_angles > 0) & (motion.foot_angles < np.pi)
    assert not upward[int(motion.valid[:30].sum())]  # sample k = 30 is not counted
    ref = reference.evaluate_reference(genome, "Fp", mode)
    if mode == "paper":  # 7 with the one-reciprocal triangle form (docs/simulator.md)
        assert ref.angle_error[0] == upward.sum() == 7
    kernel = sim.evaluate(genome, "Fp", mode)
    assert_evaluations_equal(kernel, ref, genome)


def test_helpers_compile_inlined_with_noalias_arrays():
    """The build `sim_throughput` measures: a numba without the `noalias` flag would fall
    back, silently, to the slower build (equal outputs), and this would say so."""
    from linkevo.sim.linkage import kernels

    assert kernels.NOALIAS == {"_noalias": True}
    assert kernels._JIT["_noalias"] and kernels._JIT["forceinline"]
    assert kernels.place_triangle.targetoptions["_noalias"]


@pytest.mark.parametrize("mode", sim.MODES)
def test_evaluate_equals_reference_on_20000_random_and_mutated_genomes(large_set, mode):
    """The (-pi, pi] angle convention disagreed with the spec's F_ae on about a quarter."""
    kernel = sim.evaluate(large_set, "Fp", mode)
    assert_evaluations_equal(kernel, reference.evaluate_reference(large_set, "Fp", mode), large_set)
