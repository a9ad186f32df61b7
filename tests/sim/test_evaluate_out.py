"""Tests `sim.evaluate(..., out=...)`: writing results into caller-owned arrays."""

from __future__ import annotations

import numpy as np
import pytest

from linkevo.sim import Evaluation, evaluate, random_genomes
from linkevo.sim.linkage.evaluation import ALIGNMENT, field_shapes


@pytest.mark.parametrize("fitness", ["Fp", "Fsl", "Fp2", "Fsl2"])
def test_results_written_into_a_buffer_equal_fresh_ones(fitness):
    genomes = random_genomes(np.random.default_rng(5), 57)
    n_objectives = 2 if fitness.endswith("2") else 1
    buffer = bytearray(ALIGNMENT + Evaluation.nbytes_for(57, 40, n_objectives))
    out = Evaluation.empty(57, 40, n_objectives, buffer=buffer, offset=ALIGNMENT)
    assert evaluate(genomes, fitness, out=out) is out
    fresh = evaluate(genomes, fitness)
    got = out.arrays()
    assert sorted(got) == sorted(name for name, _, _ in field_shapes(57, 40, n_objectives))
    for name, want in fresh.arrays().items():
        np.testing.assert_array_equal(got[name], want, err_msg=name)
    # The arrays really live in the buffer, each on its own 64-byte boundary.
    base = np.frombuffer(buffer, np.uint8).ctypes.data
    offsets = sorted(a.ctypes.data - base for a in (out.loss, out.foot_x, out.valid))
    assert offsets[0] == ALIGNMENT and all(o % ALIGNMENT == 0 for o in offsets)


def test_out_of_the_wrong_layout_is_refused_before_any_work():
    genomes = random_genomes(np.random.default_rng(0), 4)
    with pytest.raises(ValueError, match=r"out loss must be .* shape \(4, 2\)"):
        evaluate(genomes, "Fp2", out=Evaluation.empty(4, 40, 1))
    with pytest.raises(ValueError, match=r"out foot_x must be .* shape \(4, 20\)"):
        evaluate(genomes, "Fp", n_angles=20, out=Evaluation.empty(4, 40, 1))
    frozen = Evaluation.empty(4, 40, 1)
    frozen.valid.flags.writeable = False
    with pytest.raises(ValueError, match="out valid must be a writable"):
        evaluate(genomes, "Fp", out=frozen)


def test_out_arrays_that_overlap_are_refused_before_any_work():
    genomes = random_genomes(np.random.default_rng(0), 4)
    shared = Evaluation.empty(4, 40, 1)
    twins = Evaluation(**{**vars(shared), "foot_y": shared.foot_x})
    twins.foot_x[:] = 7.0
    with pytest.raises(ValueError, match=r"out foot_(x|y) overlaps out foot_(x|y) in memory"):
        evaluate(genomes, "Fp", out=twins)
    assert np.all(twins.foot_x == 7.0)  # refused before the kernel wrote anything
    # A result array whose first row lies over the genomes' last genes.
    flat = np.zeros(4 * 56 + 4 * 40)
    flat[: 4 * 56] = genomes.reshape(-1)
    over = Evaluation(**{**vars(shared), "foot_x": flat[4 * 56 - 8 : 4 * 56 + 152].reshape(4, 40)})
    with pytest.raises(ValueError, match="out foot_x overlaps genomes in memory"):
        evaluate(flat[: 4 * 56].reshape(4, 56), "Fp", out=over)
