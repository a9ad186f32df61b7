"""Tests that reused result buffers never overwrite results somebody still holds."""

from __future__ import annotations

import numpy as np

from linkevo.sim import evaluate, random_genomes
from linkevo.workers.evaluators import LocalEvaluator
from linkevo.workers.result_pool import KEEP, MemoryBuffer, ResultPool


def test_local_evaluator_reuses_a_buffer_only_once_its_results_are_dropped():
    rng = np.random.default_rng(9)
    a, b, c = (random_genomes(rng, 200) for _ in range(3))
    evaluator = LocalEvaluator("Fp", "paper")
    first = evaluator(a)
    address = first.foot_x.ctypes.data
    second = evaluator(b)
    assert second.foot_x.ctypes.data != address
    np.testing.assert_array_equal(first.loss, evaluate(a, "Fp").loss)
    kept = first.foot_y[5:7]  # a view keeps the whole buffer busy
    del first
    third = evaluator(c)
    assert third.foot_x.ctypes.data not in (address, second.foot_x.ctypes.data)
    np.testing.assert_array_equal(kept, evaluate(a, "Fp").foot_y[5:7])
    del kept, third
    fourth = evaluator(c)
    assert fourth.foot_x.ctypes.data == address
    np.testing.assert_array_equal(fourth.foot_x, evaluate(c, "Fp").foot_x)
    np.testing.assert_array_equal(second.loss, evaluate(b, "Fp").loss)


def test_pool_keeps_a_bounded_number_of_buffers_and_grows_with_the_batch():
    made: list[MemoryBuffer] = []

    def make(n: int) -> MemoryBuffer:
        made.append(MemoryBuffer(n, 40, 1))
        return made[-1]

    pool = ResultPool(make)
    held = [pool.free(10).evaluation() for _ in range(KEEP + 2)]
    assert len(made) == KEEP + 2 and all(buffer.busy for buffer in made)
    held.clear()
    assert pool.free(10) is made[2]  # the two oldest were let go
    assert pool.free(11).capacity == 11
    assert len(made) == KEEP + 3
