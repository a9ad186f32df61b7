"""The `noalias` fallback: kernels compiled without the flag give the same outputs."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.linkage import kernels

SCRIPT = """
import sys
import numpy as np
from linkevo import sim
from linkevo.sim.linkage import kernels
assert kernels.NOALIAS == {} and "_noalias" not in kernels._JIT
assert "_noalias" not in kernels.place_triangle.targetoptions
genomes = np.load(sys.argv[1])
result = sim.evaluate(genomes, "Fp", "paper")
np.savez(sys.argv[2], **result.arrays())
"""


def test_a_numba_without_the_flag_gets_no_option(monkeypatch):
    from numba.core import compiler

    class FlagsWithoutNoalias:
        pass

    monkeypatch.setattr(compiler, "Flags", FlagsWithoutNoalias)
    assert kernels.enable_noalias() == {}


def test_the_switch_turns_the_option_off(monkeypatch):
    monkeypatch.setenv(kernels.NOALIAS_ENV, "0")
    assert kernels.enable_noalias() == {}


@pytest.mark.timeout(600)
def test_kernels_compiled_without_noalias_give_the_same_outputs(tmp_path):
    genomes = sim.random_genomes(np.random.default_rng(11), 400)
    np.save(tmp_path / "genomes.npy", genomes)
    env = {
        "PATH": "/usr/bin:/bin",
        kernels.NOALIAS_ENV: "0",
        "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache"),  # compiled afresh, not the cache
    }
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(tmp_path / "genomes.npy"), str(tmp_path / "out.npz")],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    fallback = np.load(tmp_path / "out.npz")
    want = sim.evaluate(genomes, "Fp", "paper").arrays()
    assert set(fallback.files) == set(want)
    for name, values in want.items():
        np.testing.assert_array_equal(fallback[name], values, err_msg=name)
