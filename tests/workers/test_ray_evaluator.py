"""Tests the evaluator actors and both batch transports against in-process evaluation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from linkevo.sim import Evaluation, GenomeError, evaluate, random_genomes
from linkevo.workers.ray_evaluator import ActorPoolEvaluator, EvaluatorWorker
from linkevo.workers.result_pool import KEEP
from linkevo.workers.shared_batch import SHARED_DIR, SharedBatch, SharedLayout

pytestmark = pytest.mark.ray


def assert_same(got: Evaluation, expected: Evaluation) -> None:
    """Asserts every field of two evaluations is identical (NaN where NaN)."""
    for name in ("loss", "error", "angle_error", "valid", "foot", "foot_x", "foot_y"):
        np.testing.assert_array_equal(getattr(got, name), getattr(expected, name), err_msg=name)
    assert got.descriptors.keys() == expected.descriptors.keys()
    for name, values in expected.descriptors.items():
        np.testing.assert_array_equal(got.descriptors[name], values, err_msg=name)


def batch_files() -> set[str]:
    return {p.name for p in SHARED_DIR.glob("linkevo-batch-*")}


def start_pool(fitness: str, shared_memory: bool, n_actors: int = 2) -> ActorPoolEvaluator:
    return ActorPoolEvaluator.start(
        n_actors=n_actors,
        cpus_per_actor=1,
        fitness=fitness,
        mode="paper",
        target="D16",
        n_angles=40,
        shared_memory=shared_memory,
    )


@pytest.mark.parametrize("shared_memory", [True, False], ids=["shared-file", "object-store"])
@pytest.mark.parametrize("fitness", ["Fp", "Fsl2"])
def test_pool_equals_in_process_evaluation(ray_local, fitness, shared_memory):
    genomes = random_genomes(np.random.default_rng(7), 301)
    before = batch_files()
    with start_pool(fitness, shared_memory) as pool:
        first = pool(genomes)
        assert_same(first, evaluate(genomes, fitness))
        again = pool(genomes[::-1].copy())
        assert_same(again, evaluate(genomes[::-1], fitness))
        # A result still held is never overwritten by later batches.
        assert_same(first, evaluate(genomes, fitness))
        way = "shared-file" if shared_memory else "object-store"
        assert pool.parts_by_transport[way] == 4 and sum(pool.parts_by_transport.values()) == 4
        assert len(batch_files() - before) == (2 if shared_memory else 0)
    assert not batch_files() - before  # every file made is gone


def test_batch_files_are_reused_once_results_are_dropped(ray_local):
    rng = np.random.default_rng(3)
    before = batch_files()
    with start_pool("Fp", shared_memory=True) as pool:
        small, large = random_genomes(rng, 10), random_genomes(rng, 500)
        for _ in range(3):  # each result is dropped before the next call
            assert_same(pool(small), evaluate(small, "Fp"))
        assert len(batch_files() - before) == 1
        assert_same(pool(large), evaluate(large, "Fp"))
        assert len(batch_files() - before) == 2  # the first holds only 10 rows
        files = batch_files()
        assert_same(pool(small), evaluate(small, "Fp"))
        assert batch_files() == files
        held = [pool(large[k::7].copy()) for k in range(6)]
        assert len(batch_files() - before) == KEEP  # older files unlinked
        for k, result in enumerate(held):  # unlinked files stay mapped while held
            assert_same(result, evaluate(large[k::7], "Fp"))
        assert len(pool(small[:0])) == 0
        one = small[:1]
        assert_same(pool(one), evaluate(one, "Fp"))
    assert not batch_files() - before  # every file made is gone


def test_actor_leaves_a_batch_on_another_node_alone(ray_local):
    import ray

    worker = (
        ray.remote(EvaluatorWorker)
        .options(num_cpus=1)
        .remote(fitness="Fp", mode="paper", target="D16", n_angles=40, threads=1)
    )
    batch = SharedBatch.create("another-node", 20, 40, 1)
    try:
        batch.genomes[:] = random_genomes(np.random.default_rng(1), 20)
        batch.evaluation().loss[:] = -1.0
        assert ray.get(worker.evaluate_shared.remote(batch.layout.as_tuple(), 0, 20)) is False
        np.testing.assert_array_equal(batch.evaluation().loss, -1.0)
        here = SharedLayout(
            **{**vars(batch.layout), "node_id": ray_local.get_runtime_context().get_node_id()}
        )
        assert ray.get(worker.evaluate_shared.remote(here.as_tuple(), 5, 20)) is True
        np.testing.assert_array_equal(batch.evaluation().loss[:5], -1.0)
        expected = evaluate(batch.genomes[5:], "Fp")
        assert_same(batch.evaluation().take(slice(5, 20)), expected)
    finally:
        batch.release()
        ray.kill(worker)
    assert not Path(batch.layout.path).exists()


def test_pool_goes_on_when_an_actor_is_killed_and_restarted(ray_local):
    import ray

    genomes = random_genomes(np.random.default_rng(21), 120)
    want = evaluate(genomes, "Fp")
    with start_pool("Fp", shared_memory=True) as pool:
        assert_same(pool(genomes), want)  # channels open
        ray.kill(pool.actors[0], no_restart=False)  # Ray restarts it (max_restarts=1)
        assert_same(pool(genomes), want)  # lost channel: the part goes through Ray
        assert_same(pool(genomes), want)  # a new channel to the restarted actor
        assert pool.parts_by_transport == {"shared-file": 6, "object-store": 0}


def test_a_bad_genome_is_named_by_its_row_in_the_whole_batch(ray_local):
    with start_pool("Fp", shared_memory=True) as pool:
        bad = random_genomes(np.random.default_rng(0), 10)
        bad[7, 3] = 1.5
        with pytest.raises(GenomeError, match=r"row 7, gene 3 is 1\.5"):
            pool(bad)
        fine = random_genomes(np.random.default_rng(2), 10)
        assert_same(pool(fine), evaluate(fine, "Fp"))


@pytest.mark.parametrize("shared_memory", [True, False], ids=["shared-file", "object-store"])
def test_a_submitted_batch_is_collected_once_and_a_dropped_one_is_drained(ray_local, shared_memory):
    rng = np.random.default_rng(12)
    first, second, third = (random_genomes(rng, 40) for _ in range(3))
    with start_pool("Fp", shared_memory) as pool:
        pending = pool.submit(first)
        assert_same(pending(), evaluate(first, "Fp"))
        with pytest.raises(RuntimeError, match="collected already"):
            pending()
        dropped = pool.submit(second)
        pending = pool.submit(third)  # waits for `second` first: no reply is left queued
        with pytest.raises(RuntimeError, match="dropped by a later submit"):
            dropped()
        assert_same(pending(), evaluate(third, "Fp"))
        assert_same(pool(second), evaluate(second, "Fp"))
        assert sum(pool.parts_by_transport.values()) == 8  # 4 batches, 2 parts each


def test_an_error_raised_in_an_actor_reaches_the_caller(ray_local):
    with start_pool("Fp", shared_memory=True) as pool:
        genomes = random_genomes(np.random.default_rng(4), 10)
        pool(genomes)  # channels open
        # A request for a batch file that does not exist fails inside the actors.
        node = ray_local.get_runtime_context().get_node_id()
        missing = SharedLayout(f"{SHARED_DIR}/linkevo-batch-missing", node, 10, 40, 1)
        request = (missing.as_tuple(), 0, 10)
        with pytest.raises(FileNotFoundError, match="linkevo-batch-missing"):
            pool._send_shared(pool.actors, [request, request])()
        assert_same(pool(genomes), evaluate(genomes, "Fp"))


def test_pool_falls_back_to_the_object_store_when_no_batch_file_can_be_made(
    ray_local, monkeypatch, tmp_path
):
    import linkevo.workers.shared_batch

    genomes = random_genomes(np.random.default_rng(8), 50)
    with start_pool("Fp", shared_memory=True) as pool:
        monkeypatch.setattr(linkevo.workers.shared_batch, "SHARED_DIR", tmp_path / "missing")
        with pytest.warns(RuntimeWarning, match="shared-memory batches unavailable"):
            assert_same(pool(genomes), evaluate(genomes, "Fp"))
        assert_same(pool(genomes), evaluate(genomes, "Fp"))
        assert pool.parts_by_transport == {"shared-file": 0, "object-store": 4}


def test_batch_files_of_dead_processes_are_removed_when_a_new_one_is_made():
    import os

    pid = next(p for p in range(2**22 - 1, 2**22 - 200, -1) if not Path(f"/proc/{p}").exists())
    orphan = SHARED_DIR / f"linkevo-batch-{pid}-0123456789ab"
    mine = SHARED_DIR / f"linkevo-batch-{os.getpid()}-ba9876543210"
    orphan.write_bytes(b"x")
    mine.write_bytes(b"x")
    try:
        batch = SharedBatch.create("node", 4, 40, 1)
        assert not orphan.exists() and mine.exists() and Path(batch.layout.path).exists()
        batch.release()
    finally:
        orphan.unlink(missing_ok=True)
        mine.unlink(missing_ok=True)
