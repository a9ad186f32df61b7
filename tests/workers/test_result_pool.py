"""Tests that reused result buffers never overwrite results somebody still holds."""

from __future__ import annotations

import numpy as np

from linkevo.sim import evaluate, random_genomes
from linkevo.workers.evaluators import LocalEvaluator
from linkevo.workers.result_pool import KEEP, ResultPool


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
    pool = ResultPool(40, 1)
    made = [pool.free(10) for _ in range(KEEP + 2)]
    held = [buffer.evaluation() for buffer in made]
    assert len({id(b) for b in made}) == 1  # nobody held the first: it was handed out again
    made, held = [], []
    for _ in range(KEEP + 2):
        made.append(pool.free(10))
        held.append(made[-1].evaluation())
    assert len({id(b) for b in made}) == KEEP + 2 and all(buffer.busy for buffer in made)
    held.clear()
    assert not any(buffer.busy for buffer in made)
    assert pool.free(10) is made[2]  # the two oldest were let go
    bigger = pool.free(11)
    assert bigger.capacity == 11 and bigger not in made
