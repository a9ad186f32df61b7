"""MAP-Elites archive insertion rules, re-indexing and scores."""

from __future__ import annotations

import numpy as np
import pytest

from linkevo.algorithms.archive import GridArchive
from linkevo.algorithms.individuals import Individuals
from linkevo.sim.linkage.descriptors import DESCRIPTOR_SPACES


def batch(loss: list[float], desc: list[list[float]], tag: float = 0.0) -> Individuals:
    n = len(loss)
    genome = np.full((n, 56), tag) + np.arange(n)[:, None] * 1e-3
    return Individuals(
        genome=genome,
        sigma=np.full((n, 1), 0.1),
        loss=np.asarray(loss, dtype=float),
        error=np.zeros(n, dtype=np.int64),
        angle_error=np.zeros(n),
        desc=np.asarray(desc, dtype=float),
        foot_x=np.zeros((n, 3)),
        foot_y=np.zeros((n, 3)),
    )


@pytest.fixture
def archive() -> GridArchive:
    return GridArchive(space=DESCRIPTOR_SPACES["MAP-LIS"])


def test_empty_cell_takes_the_child(archive: GridArchive) -> None:
    assert archive.add(batch([5.0], [[2.05, 3.3]])) == 1
    assert len(archive) == 1
    np.testing.assert_array_equal(archive.bins(archive.elites.desc), [[20, 6]])
    assert archive.cells[0] == 20 * 100 + 6


def test_better_child_replaces_worse_does_not(archive: GridArchive) -> None:
    archive.add(batch([5.0], [[2.05, 3.3]], tag=0.1))
    assert archive.add(batch([7.0], [[2.08, 3.2]], tag=0.2)) == 0
    assert archive.elites.loss[0] == 5.0 and archive.elites.genome[0, 0] == 0.1
    assert archive.add(batch([5.0], [[2.08, 3.2]], tag=0.3)) == 0  # a tie keeps the elite
    assert archive.elites.genome[0, 0] == 0.1
    assert archive.add(batch([4.0], [[2.02, 3.4]], tag=0.4)) == 1
    assert len(archive) == 1
    assert archive.elites.loss[0] == 4.0 and archive.elites.genome[0, 0] == 0.4


def test_two_children_for_one_cell_keep_the_better(archive: GridArchive) -> None:
    added = archive.add(
        batch([6.0, 3.0, 9.0, 1.0], [[2.05, 3.3], [2.06, 3.1], [0.5, 0.2], [9, 40]])
    )
    assert added == 3
    np.testing.assert_array_equal(archive.elites.loss, [9.0, 3.0, 1.0])  # sorted by cell
    assert archive.cells.tolist() == sorted(archive.cells.tolist())


def test_non_finite_losses_are_refused(archive: GridArchive) -> None:
    assert archive.add(batch([np.nan, np.inf, 2.0], [[1, 1], [2, 2], [3, 3]])) == 1
    np.testing.assert_array_equal(archive.elites.loss, [2.0])


def test_reindex_keeps_the_best_of_colliding_elites(archive: GridArchive) -> None:
    archive.add(batch([3.0, 1.0, 2.0, 4.0], [[1, 1], [2, 2], [3, 3], [4, 4]]))
    dropped = archive.reindex(np.array([[5.0, 5.0], [5.0, 5.0], [5.0, 5.0], [0.0, 0.0]]))
    assert dropped == 2
    np.testing.assert_array_equal(archive.elites.loss, [4.0, 1.0])
    np.testing.assert_array_equal(archive.elites.desc, [[0.0, 0.0], [5.0, 5.0]])


def test_coverage_and_qd_score(archive: GridArchive) -> None:
    archive.add(batch([3.0, 1.0, 1500.0], [[1, 1], [2, 2], [3, 3]]))
    assert archive.coverage() == pytest.approx(3 / 10_000)
    assert archive.qd_score(1000.0) == pytest.approx(997.0 + 999.0)


def test_state_dict_round_trip(archive: GridArchive) -> None:
    archive.add(batch([3.0, 1.0], [[1, 1], [2, 2]]))
    copy = GridArchive(space=DESCRIPTOR_SPACES["MAP-LIS"])
    copy.load_state_dict(archive.state_dict())
    np.testing.assert_array_equal(copy.cells, archive.cells)
    np.testing.assert_array_equal(copy.elites.genome, archive.elites.genome)


def test_the_repertoire_is_a_pyribs_archive_with_the_published_bins(archive: GridArchive) -> None:
    from ribs.archives import GridArchive as RibsGridArchive

    edges = np.array([[0.1, 0.5], [0.1000001, 0.5000001], [9.9, 49.5], [10.0, 50.0]])
    archive.add(batch([1.0, 2.0, 3.0, 4.0], edges))
    assert isinstance(archive._grid, RibsGridArchive)
    # A value on an edge belongs to the bin below it (v > i*step counts i).
    np.testing.assert_array_equal(archive.bins(edges), [[0, 0], [1, 1], [98, 98], [99, 99]])
    assert archive.cells.tolist() == [0, 101, 98 * 100 + 98, 99 * 100 + 99]


def test_insertion_matches_a_plain_per_child_archive(archive: GridArchive) -> None:
    """Random batches with repeated losses and edge values, against a dict archive."""
    rng = np.random.default_rng(5)
    plain: dict[int, tuple[float, float]] = {}  # cell -> (loss, tag)
    for step in range(12):
        n = 300
        desc = rng.integers(0, 12, size=(n, 2)) * np.array([0.1, 0.5])
        desc += rng.choice([0.0, 0.05], size=(n, 2))  # half of the values sit on an edge
        loss = rng.integers(0, 6, size=n).astype(float)
        loss[rng.random(n) < 0.05] = np.nan
        genome_tag = step + np.arange(n) / 1000
        child = batch(loss.tolist(), desc.tolist())
        child = Individuals(**{**child.__dict__, "genome": np.repeat(genome_tag[:, None], 56, 1)})
        for cell, value, tag in zip(archive.cell_index(desc), loss, genome_tag, strict=True):
            if np.isfinite(value) and (cell not in plain or value < plain[cell][0]):
                plain[int(cell)] = (float(value), float(tag))
        archive.add(child)
        assert archive.cells.tolist() == sorted(plain)
        np.testing.assert_array_equal(archive.elites.loss, [plain[c][0] for c in sorted(plain)])
        np.testing.assert_array_equal(
            archive.elites.genome[:, 0], [plain[c][1] for c in sorted(plain)]
        )


def test_a_state_of_another_grid_is_refused(archive: GridArchive) -> None:
    archive.add(batch([3.0, 1.0], [[1, 1], [2, 2]]))
    other = GridArchive(space=DESCRIPTOR_SPACES["MAP-WH"])
    with pytest.raises(ValueError, match="do not bin to their saved cells in the height/width"):
        other.load_state_dict(archive.state_dict())
