"""MAP-AU gives the same bits for a seed whatever CPU numba compiles its kernels for."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from tests.helpers.aurora_fingerprint import fingerprint

ROOT = Path(__file__).resolve().parents[2]


def test_a_map_au_trial_is_the_same_compiled_for_the_baseline_x86_64(tmp_path) -> None:
    """The host build (this CPU's vector width and FMA) against numba's `generic` target
    (baseline x86-64: SSE2, no FMA), each from its own compile cache. With reassociated
    sums or fused multiply-adds the two part after the first training."""
    here = fingerprint()
    env = {**os.environ, "NUMBA_CPU_NAME": "generic", "NUMBA_CACHE_DIR": str(tmp_path)}
    run = subprocess.run(
        [sys.executable, "-m", "tests.helpers.aurora_fingerprint"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=True,
    )
    generic = json.loads(run.stdout.strip().splitlines()[-1])
    assert int(here["elites"]) > 100
    assert generic == here
