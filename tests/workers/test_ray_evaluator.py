"""Tests the evaluator actors against in-process evaluation."""

from __future__ import annotations

import numpy as np
import pytest

from linkevo.sim import Evaluation, GenomeError, evaluate, random_genomes
from linkevo.workers.ray_evaluator import ActorPoolEvaluator

pytestmark = pytest.mark.ray


def assert_same(got: Evaluation, expected: Evaluation) -> None:
    """Asserts every field of two evaluations is identical (NaN where NaN)."""
    for name in ("loss", "error", "angle_error", "valid", "foot", "foot_x", "foot_y"):
        np.testing.assert_array_equal(getattr(got, name), getattr(expected, name), err_msg=name)
    assert got.descriptors.keys() == expected.descriptors.keys()
    for name, values in expected.descriptors.items():
        np.testing.assert_array_equal(got.descriptors[name], values, err_msg=name)


def start_pool(fitness: str, n_actors: int = 2) -> ActorPoolEvaluator:
    return ActorPoolEvaluator.start(
        n_actors=n_actors,
        cpus_per_actor=1,
        fitness=fitness,
        mode="paper",
        target="D16",
        n_angles=40,
    )


@pytest.mark.parametrize("fitness", ["Fp", "Fsl2"])
def test_pool_equals_in_process_evaluation(ray_local, fitness):
    genomes = random_genomes(np.random.default_rng(7), 301)
    with start_pool(fitness) as pool:
        first = pool(genomes)
        assert_same(first, evaluate(genomes, fitness))
        again = pool(genomes[::-1].copy())
        assert_same(again, evaluate(genomes[::-1], fitness))
        assert_same(first, evaluate(genomes, fitness))  # a result held stays as it was
        assert_same(pool(genomes[:1]), evaluate(genomes[:1], fitness))  # fewer rows than actors


def test_pool_goes_on_when_an_actor_is_killed_and_restarted(ray_local):
    import ray

    genomes = random_genomes(np.random.default_rng(21), 120)
    want = evaluate(genomes, "Fp")
    with start_pool("Fp") as pool:
        assert_same(pool(genomes), want)
        ray.kill(pool.actors[0], no_restart=False)  # Ray restarts it (max_restarts=1)
        assert_same(pool(genomes), want)  # the part is retried on the restarted actor
        assert_same(pool(genomes), want)


def test_a_bad_genome_is_named_by_its_row_in_the_whole_batch(ray_local):
    with start_pool("Fp") as pool:
        bad = random_genomes(np.random.default_rng(0), 10)
        bad[7, 3] = 1.5
        with pytest.raises(GenomeError, match=r"row 7, gene 3 is 1\.5"):
            pool(bad)
        fine = random_genomes(np.random.default_rng(2), 10)
        assert_same(pool(fine), evaluate(fine, "Fp"))


def test_a_submitted_batch_is_collected_once_and_a_dropped_one_is_drained(ray_local):
    rng = np.random.default_rng(12)
    first, second, third = (random_genomes(rng, 40) for _ in range(3))
    with start_pool("Fp") as pool:
        pending = pool.submit(first)
        assert_same(pending(), evaluate(first, "Fp"))
        with pytest.raises(RuntimeError, match="collected already"):
            pending()
        dropped = pool.submit(second)
        pending = pool.submit(third)  # waits for `second` first
        with pytest.raises(RuntimeError, match="dropped by a later submit"):
            dropped()
        assert_same(pending(), evaluate(third, "Fp"))
        assert_same(pool(second), evaluate(second, "Fp"))


def test_an_error_raised_in_an_actor_reaches_the_caller(ray_local):
    import ray

    with start_pool("Fp") as pool:
        genomes = random_genomes(np.random.default_rng(4), 10)
        direct = ray.get(pool.actors[0].evaluate.remote(genomes))
        assert_same(direct, evaluate(genomes, "Fp"))
        with pytest.raises(ray.exceptions.RayTaskError, match="GenomeError"):
            ray.get(pool.actors[0].evaluate.remote(np.full((2, 56), np.nan)))
        assert_same(pool(genomes), evaluate(genomes, "Fp"))


def test_a_walking_trial_on_two_actors_equals_one_in_process(ray_local, tmp_path):
    """Candidates walked on evaluator actors, one task each: the same trial, bit for bit,
    as walked here, whichever actor took which candidate; each names its Ray node."""
    import pandas as pd

    from linkevo.workers.evaluators import make_evaluator
    from linkevo.workers.recorders import NullRecorder
    from linkevo.workers.trial import run_trial
    from linkevo.workers.trial_spec import TrialSpec

    spec = TrialSpec.walking("MAP-LIS", 24, seed=3)
    here = run_trial(spec, make_evaluator(spec), NullRecorder(), tmp_path / "here")
    with make_evaluator(spec, actors=2) as evaluator:
        there = run_trial(spec, evaluator, NullRecorder(), tmp_path / "actors")
    assert (here.out_dir / "metrics.csv").read_text() == (there.out_dir / "metrics.csv").read_text()
    logs = [pd.read_parquet(r.out_dir / "walks.parquet") for r in (here, there)]
    same = [c for c in logs[0].columns if c not in ("node", "compute_s", "genome")]
    pd.testing.assert_frame_equal(logs[0][same], logs[1][same])
    node = ray_local.get_runtime_context().get_node_id()
    assert set(logs[1].loc[logs[1]["stage"] != "seeded", "node"]) == {node}
