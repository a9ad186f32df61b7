"""Tests that a grid survives losing a worker node of a multi-node Ray cluster."""

from __future__ import annotations

import threading
import time

import pytest

from linkevo.orchestrator.driver import launch
from linkevo.workers.store.tracking import ensure_experiment
from tests.helpers.grid import running_on, runs_by_key, tiny_grid

pytestmark = pytest.mark.ray

NODE_ARGS = {"num_cpus": 1, "object_store_memory": 100 * 1024**2}


@pytest.fixture(scope="module")
def cluster():
    """A head and two 1-CPU worker nodes on this machine."""
    import ray
    from ray.cluster_utils import Cluster

    nodes = Cluster(initialize_head=True, head_node_args={**NODE_ARGS, "include_dashboard": False})
    workers = [nodes.add_node(**NODE_ARGS) for _ in range(2)]
    nodes.wait_for_nodes()
    ray.init(address=nodes.address)
    yield nodes, workers
    ray.shutdown()
    nodes.shutdown()


def test_grid_survives_removing_a_worker_node(cluster, tmp_path):
    nodes, workers = cluster
    grid = tiny_grid(tmp_path, approaches=["EA", "MAP-LIS"], fitnesses=["Fp"], evaluations=2000)
    uri = grid.config.tracking_uri
    ensure_experiment(uri)
    outcome = {}
    driver = threading.Thread(target=lambda: outcome.update(result=launch(grid, progress=False)))
    driver.start()
    victim = workers[0]
    deadline = time.monotonic() + 180
    key = None
    while key is None:
        assert time.monotonic() < deadline, "no trial ran on the worker node"
        assert driver.is_alive(), "the grid ended before a trial ran on the worker node"
        key = running_on(uri, grid.grid_id, victim.node_id)
        time.sleep(0.1)
    nodes.remove_node(victim)
    nodes.add_node(**NODE_ARGS)
    driver.join(timeout=240)
    assert not driver.is_alive()
    result = outcome["result"]
    assert not result.failed
    by_key = runs_by_key(uri, grid.grid_id)
    assert sorted(by_key) == sorted(c.key for c in grid.cells)
    for runs in by_key.values():
        assert [status for _, status in runs].count("FINISHED") == 1
    assert sorted(status for _, status in by_key[key]) == ["FINISHED", "KILLED"]


def test_actors_on_two_nodes_evaluate_a_batch_as_one_process_does(cluster):
    import numpy as np
    import ray
    from ray.util.placement_group import (
        placement_group,
        placement_group_table,
        remove_placement_group,
    )

    from linkevo.sim import evaluate, random_genomes
    from linkevo.workers.ray_evaluator import ActorPoolEvaluator

    group = placement_group([{"CPU": 1}, {"CPU": 1}], strategy="STRICT_SPREAD")
    ray.get(group.ready(), timeout=60)
    try:
        nodes = set(placement_group_table(group)["bundles_to_node_id"].values())
        assert len(nodes) == 2 and nodes - {ray.get_runtime_context().get_node_id()}
        genomes = random_genomes(np.random.default_rng(11), 200)
        with ActorPoolEvaluator.start(
            n_actors=2,
            cpus_per_actor=1,
            fitness="Fp",
            mode="paper",
            target="D16",
            n_angles=40,
            placement_group=group,
        ) as pool:
            got = pool(genomes)
        want = evaluate(genomes, "Fp")
        np.testing.assert_array_equal(got.loss, want.loss)
        np.testing.assert_array_equal(got.foot_y, want.foot_y)
    finally:
        remove_placement_group(group)
