"""Tests for the JSON linkage document: export, load, re-simulate."""

from __future__ import annotations

import json

import numpy as np
import pytest

from linkevo import sim
from linkevo.sim.linkage.linkage_doc import FORMAT, from_document, to_document


@pytest.fixture(scope="module")
def valid_genomes() -> np.ndarray:
    genomes = sim.random_genomes(np.random.default_rng(11), 400)
    ok = sim.evaluate(genomes).error == 0
    return genomes[ok][:5]


@pytest.mark.parametrize("mode", ["paper", "legacy"])
def test_export_load_resimulate_reproduces_foot_path(valid_genomes, mode):
    for genome in valid_genomes:
        text = json.dumps(to_document(genome, mode))
        loaded, loaded_mode = from_document(json.loads(text))
        assert loaded_mode == mode
        np.testing.assert_array_equal(loaded, genome)
        original = sim.evaluate(genome[None], mode=mode)
        again = sim.evaluate(loaded[None], mode=mode)
        np.testing.assert_array_equal(again.foot_x, original.foot_x)
        np.testing.assert_array_equal(again.foot_y, original.foot_y)
        doc = json.loads(text)
        np.testing.assert_allclose(doc["foot_path"]["x"], original.foot_x[0], atol=1e-12)


def test_document_lists_nodes_beams_crank_and_foot(valid_genomes):
    genome = valid_genomes[0]
    doc = to_document(genome, "paper", unit_mm=8.0)
    batch = sim.decode(genome[None])
    assert doc["format"] == FORMAT
    assert doc["units"]["unit_mm"] == 8.0
    assert len(doc["nodes"]) == 12
    assert [n["kind"] for n in doc["nodes"][:5]] == ["motor", "static", "static", "static", "crank"]
    assert len(doc["beams"]) == int(batch.n_beams[0])
    for beam in doc["beams"]:
        start = np.array([doc["nodes"][beam["start"]][c] for c in "xy"])
        end = np.array([doc["nodes"][beam["end"]][c] for c in "xy"])
        assert beam["length_mm"] == pytest.approx(beam["length"] * 8.0)
        if beam["kind"] != "triangle":
            assert np.hypot(*(end - start)) == pytest.approx(beam["length"], abs=1e-9)
    assert doc["crank"]["length"] == pytest.approx(2 + 6 * genome[6])
    assert doc["foot"] == int(sim.evaluate(genome[None]).foot[0])


def test_edited_document_is_refused(valid_genomes):
    doc = to_document(valid_genomes[0], "paper")
    doc["beams"][1]["length"] += 0.5
    with pytest.raises(ValueError, match="do not match"):
        from_document(doc)
    with pytest.raises(ValueError, match="not a readable linkage document"):
        from_document({"format": "something else"})
    bad = to_document(valid_genomes[0], "paper")
    bad["genome"][3] = 1.5
    with pytest.raises(ValueError, match="gene 3"):
        from_document(bad)


def assert_same_motion(got: sim.Motion, want: sim.Motion) -> None:
    for name in ("positions", "valid", "beam_angles", "foot"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)


@pytest.mark.parametrize("mode", ["paper", "legacy"])
def test_the_document_alone_rebuilds_the_genomes_simulation(mode):
    """Thousands of random linkages (valid or not): a JSON round trip of the document,
    rebuilt without its genome, simulates to the same bits as the genome."""
    from linkevo.sim.linkage.linkage_doc import batch_from_document, simulate_document

    genomes = sim.random_genomes(np.random.default_rng(23 if mode == "paper" else 29), 1500)
    want = sim.simulate(sim.decode(genomes, mode), 24)
    for i, genome in enumerate(genomes):
        doc = json.loads(json.dumps(to_document(genome, mode, n_angles=24)))
        doc["genome"] = None  # not read
        got = simulate_document(doc)
        one = sim.Motion(
            *(getattr(want, f)[i : i + 1] for f in ("positions", "valid", "beam_angles", "foot"))
        )
        assert_same_motion(got, one)
    batch = batch_from_document(to_document(genomes[0], mode))
    np.testing.assert_array_equal(batch.node_int, sim.decode(genomes[:1], mode).node_int)


def test_the_document_states_the_crank_sense_angles_and_topology(valid_genomes):
    doc = to_document(valid_genomes[0], "paper", n_angles=8)
    np.testing.assert_allclose(doc["crank"]["angles"], np.arange(8) * 2 * np.pi / 8)
    assert doc["tolerance"] == 0.1
    kinds = {n["kind"]: n["topology"] for n in doc["nodes"]}
    assert set(kinds["triangle"]) == {
        "anchors",
        "lengths",
        "branch",
        "backup_angle",
        "backup_offset",
    }
    for node in doc["nodes"][1:4]:  # the static nodes sit where their topology says
        assert node["topology"] == {"x": node["x"], "y": node["y"]}
    for beam in doc["beams"][1:]:
        assert beam["root"] >= 0 and beam["inversions"] >= 0
