"""Tests for `sim.linkage.pylinkage_export`: a document's pylinkage Linkage moves as linkevo's."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim import decode, simulate
from linkevo.sim.linkage.linkage_doc import to_document
from linkevo.sim.linkage.physical import physical_checks
from linkevo.sim.linkage.pylinkage_export import to_pylinkage

SUBSTEPS = 10


@pytest.mark.parametrize("mode", ["paper", "legacy"])
def test_pylinkage_follows_linkevo_on_rigid_linkages_without_toggles(mode):
    genomes = sim.random_genomes(np.random.default_rng(3), 2000)
    batch = decode(genomes, mode)
    motion = simulate(batch, 40)
    checks = physical_checks(batch, motion)
    rigid = checks.turns_fully & (checks.max_stretch < 1e-9) & (checks.toggle_passages == 0)
    chosen = np.flatnonzero(rigid)[:80]
    assert len(chosen) == 80
    kinds = set()
    for i in chosen:
        doc = to_document(genomes[i], mode)
        kinds |= {n["kind"] for n in doc["nodes"]}
        linkage = to_pylinkage(doc)
        steps = linkage.step(iterations=40 * SUBSTEPS, dt=1 / SUBSTEPS)
        theirs = np.array(list(steps), dtype=float)[SUBSTEPS - 1 :: SUBSTEPS]  # (40, 12, 2)
        ours = np.roll(motion.positions[i].transpose(1, 0, 2), -1, axis=0)  # from sample 1
        assert np.abs(theirs - ours).max() < 1e-9
    assert kinds == {"motor", "static", "crank", "triangle", "extension"}


def test_without_pylinkage_the_error_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "pylinkage", None)  # import pylinkage now fails
    with pytest.raises(ImportError, match=r"pip install pylinkage"):
        to_pylinkage(to_document(sim.random_genomes(np.random.default_rng(0), 1)[0]))
