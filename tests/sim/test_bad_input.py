"""Bad genomes and options are refused with a clear error; degenerate linkages stay finite."""

from __future__ import annotations

import math

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.linkage import reference
from linkevo.sim.linkage.fitness import named_target

EVALUATORS = [sim.evaluate, reference.evaluate_reference]


@pytest.mark.parametrize("evaluate", EVALUATORS)
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, -0.1, 1.0, 1.5, -1e-300])
def test_out_of_range_gene_is_refused_naming_row_gene_and_value(evaluate, value):
    genomes = np.full((5, sim.N_GENES), 0.5)
    genomes[3, 17] = value
    with pytest.raises(sim.GenomeError) as info:
        evaluate(genomes)
    message = str(info.value)
    assert "row 3" in message and "gene 17" in message and repr(value) in message
    assert "[0, 1)" in message


@pytest.mark.parametrize("evaluate", EVALUATORS)
@pytest.mark.parametrize("shape", [(56,), (2, 55), (2, 57), (2, 56, 1), ()])
def test_wrong_shape_is_refused_naming_the_shape(evaluate, shape):
    with pytest.raises(sim.GenomeError, match=r"shape \(N, 56\)") as info:
        evaluate(np.full(shape, 0.5))
    assert str(shape) in str(info.value)


@pytest.mark.parametrize("evaluate", EVALUATORS)
@pytest.mark.parametrize(
    "genomes",
    [
        np.full((2, 56), "0.5"),
        np.full((2, 56), 0.5, dtype=object),
        np.full((2, 56), 0.5 + 0j),
        np.zeros((2, 56), dtype=bool),
    ],
    ids=["strings", "objects", "complex", "bool"],
)
def test_non_real_dtype_is_refused_naming_the_dtype(evaluate, genomes):
    with pytest.raises(sim.GenomeError, match="dtype") as info:
        evaluate(genomes)
    assert str(genomes.dtype) in str(info.value)


@pytest.mark.parametrize("evaluate", EVALUATORS)
@pytest.mark.parametrize(
    ("option", "value"),
    [("fitness", "Fx"), ("mode", "modern"), ("n_angles", 1), ("n_angles", 2.5)],
)
def test_bad_option_is_refused_naming_the_value(evaluate, option, value):
    genomes = np.full((2, sim.N_GENES), 0.5)
    with pytest.raises(ValueError, match=str(value)):
        evaluate(genomes, **{option: value})


def test_nested_lists_and_integer_arrays_are_accepted():
    as_list = np.full((2, sim.N_GENES), 0.5).tolist()
    np.testing.assert_allclose(
        sim.evaluate(as_list).loss, reference.evaluate_reference(as_list).loss, atol=1e-9
    )
    assert len(sim.evaluate(np.zeros((3, sim.N_GENES), dtype=np.int64))) == 3


def only_angle_zero(builder) -> np.ndarray:
    """Returns a genome that assembles at crank angle 0 only, in both modes.

    An extension carries the crank tip's direction out to radius 8 (crank 3, extension 5,
    which is also the legacy extension length 12 * g6 + 3); a triangle from it to the
    static node (5, 0) has l1 + l2 = 3, the minimal distance reached at angle 0. Already at
    the next angle (9 degrees) the distance exceeds 3 + t, so every other angle fails.
    """
    b = builder(statics=((5, 0), (-5, 5), (5, 5)), crank=3.0)
    outer = b.extension(0, 5.0)
    b.triangle(outer, 1, 2.0, 1.0)
    return b.genome()


@pytest.mark.parametrize("mode", sim.MODES)
@pytest.mark.parametrize("fitness", sim.PATH_FITNESSES)
def test_linkage_valid_only_at_angle_zero_gets_finite_losses(builder, mode, fitness):
    genome = only_angle_zero(builder)[None]
    ev = sim.evaluate(genome, fitness, mode)
    ref = reference.evaluate_reference(genome, fitness, mode)
    assert ev.error[0] == ref.error[0] == 39
    assert ev.valid[0].tolist() == [True] + [False] * 39
    assert np.isfinite(ev.loss).all() and np.isfinite(ev.angle_error).all()
    assert np.isfinite(ev.foot_x[0, 0]) and np.isnan(ev.foot_x[0, 1:]).all()
    for values in ev.descriptors.values():
        assert np.isfinite(values).all()
    np.testing.assert_allclose(ev.loss, ref.loss, atol=1e-9)
    if fitness.startswith("Fsl"):  # one sample: no step, no lift
        np.testing.assert_allclose(ev.loss, ev.error[0] + ev.angle_error[0])


def test_target_is_a_target_or_a_published_name():
    genomes = sim.random_genomes(np.random.default_rng(4), 50)
    by_name = sim.evaluate(genomes, target="D24").loss
    np.testing.assert_array_equal(by_name, sim.evaluate(genomes, target=named_target("D24")).loss)
    with pytest.raises(ValueError, match="unknown target 'D99'"):
        sim.evaluate(genomes, target="D99")
    with pytest.raises(ValueError, match="target must be a Target"):
        sim.evaluate(genomes, target=42)
