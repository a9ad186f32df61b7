"""Shared fixtures for the simulator tests: a genome builder and genome sets."""

from __future__ import annotations

import math

import numpy as np
import pytest

from linkevo.sim.linkage import reference
from linkevo.sim.linkage.genome import BLOCK_SIZE, CRANK_GENE, FIRST_BLOCK, N_BLOCKS, N_GENES

TRIANGLE_GENE = 0.5
EXTENSION_GENE = 0.1
EDGE_VALUES = (0.0, 0.25, 0.5, 0.75, 1.0 / 11.0, 2.0 / 11.0, 1.0 / 3.0, 0.5 - 2.0**-54)
"""Genes at exact bin edges (and just below one) of the decoding formulas."""


def _pick(index: int, count: int) -> float:
    """Returns the gene whose fti(gene, count) is index (the middle of its bin)."""
    assert 0 <= index < count, (index, count)
    return (index + 0.5) / count


def _unit(value: float, low: float, high: float) -> float:
    """Returns the gene g with value = (high - low) * g + low, asserting g in [0, 1)."""
    gene = (value - low) / (high - low)
    assert 0.0 <= gene < 1.0, f"{value} is outside the decodable range [{low}, {high})"
    return gene


class GenomeBuilder:
    """Builds a genome from a mechanism description by inverting the decoding formulas.

    Blocks are added in order; the blocks not described are filled with a static triangle
    anchored at `filler_anchors` (two static nodes), placed on the higher side, so that it
    never fails and never becomes the foot of a mechanism below it.
    """

    def __init__(
        self,
        statics: tuple[tuple[int, int], ...] = ((-4, 0), (-5, 5), (5, 5)),
        crank: float = 2.0,
        mode: str = "paper",
        filler_anchors: tuple[int, int] = (2, 3),
    ) -> None:
        self.genes = np.zeros(N_GENES)
        for j, (x, y) in enumerate(statics):
            self.genes[2 * j] = _pick(x + 5, 11)
            self.genes[2 * j + 1] = _pick(y + 5, 11)
        self.genes[CRANK_GENE] = _unit(crank, 2.0, 8.0)
        self.mode = mode
        self.filler_anchors = filler_anchors
        self.n_blocks = 0

    def _offset(self) -> int:
        assert self.n_blocks < N_BLOCKS, "all seven blocks are used"
        return FIRST_BLOCK + BLOCK_SIZE * self.n_blocks

    def _decoded(self) -> reference.Linkage:
        return reference.decode_linkage(self.genome(), self.mode)

    def triangle(
        self,
        a: int,
        c: int,
        l1: float,
        l2: float,
        direction: int = 0,
        backup_angle: float = 0.0,
    ) -> int:
        """Adds a node held by l1 from node a and l2 from node c; returns its index."""
        node = 5 + self.n_blocks
        nodes = self._decoded().nodes
        d = math.dist(nodes[a], nodes[c])
        o = self._offset()
        s1 = max(d - 15.0, 2.0)
        lo, hi = abs(d - l1), min(d + l1, 15.0)
        self.genes[o : o + BLOCK_SIZE] = [
            TRIANGLE_GENE,
            _pick(a - 1, node - 1),
            _pick(c - 1, node - 1),
            _pick(direction, 2),
            backup_angle / (2.0 * math.pi),
            _unit(l1, s1, 15.0),
            _unit(l2, lo, hi) if hi > lo else 0.0,
        ]
        self.n_blocks += 1
        block = self._decoded().blocks[node - 5]
        assert (block.anchor_a, block.anchor_c) == (a, c), "anchor C was repaired"
        return node

    def extension(self, parent: int, length: float | None = None, inverted: bool = False) -> int:
        """Adds a node continuing beam `parent` by `length` (paper mode); returns its index."""
        node = 5 + self.n_blocks
        blocks = self._decoded().blocks[: self.n_blocks]
        n_beams = 1 + sum(1 if isinstance(b, reference.Extension) else 2 for b in blocks)
        o = self._offset()
        self.genes[o : o + BLOCK_SIZE] = [
            EXTENSION_GENE,
            _pick(parent, n_beams),
            0.0,
            _pick(int(inverted), 2),
            0.0,
            0.0,
            0.0 if length is None else _unit(length, 2.0, 15.0),
        ]
        self.n_blocks += 1
        return node

    def genome(self) -> np.ndarray:
        """Returns the genome (56,), the unused blocks filled with static triangles."""
        genes = self.genes.copy()
        a, c = self.filler_anchors
        for i in range(self.n_blocks, N_BLOCKS):
            o = FIRST_BLOCK + BLOCK_SIZE * i
            n_before = 4 + i
            genes[o : o + BLOCK_SIZE] = [
                TRIANGLE_GENE,
                _pick(a - 1, n_before),
                _pick(c - 1, n_before),
                _pick(1, 2),
                0.0,
                0.5,
                0.5,
            ]
        return genes


@pytest.fixture
def builder() -> type[GenomeBuilder]:
    """Returns the GenomeBuilder class."""
    return GenomeBuilder


def heavily_mutated(rng: np.random.Generator, n: int) -> np.ndarray:
    """Returns n genomes (n, 56) with 30-60% of genes in [0, 1e-3) and ~10% at bin edges."""
    genomes = rng.random((n, N_GENES))
    near_zero = rng.random((n, N_GENES)) < rng.uniform(0.3, 0.6, (n, 1))
    genomes[near_zero] = rng.random(int(near_zero.sum())) * 1e-3
    edge = rng.random((n, N_GENES)) < 0.1
    genomes[edge] = rng.choice(EDGE_VALUES, int(edge.sum()))
    return genomes


@pytest.fixture(scope="session")
def random_set() -> np.ndarray:
    """1,000 uniform random genomes (1000, 56)."""
    return np.random.default_rng(20261121).random((1000, N_GENES))


@pytest.fixture(scope="session")
def mutated_set() -> np.ndarray:
    """1,500 heavily mutated genomes (1500, 56)."""
    return heavily_mutated(np.random.default_rng(1121), 1500)


@pytest.fixture(scope="session")
def large_set() -> np.ndarray:
    """10,000 uniform random genomes, then 10,000 heavily mutated ones."""
    return np.concatenate(
        [
            np.random.default_rng(24).random((10_000, N_GENES)),
            heavily_mutated(np.random.default_rng(2024), 10_000),
        ]
    )


@pytest.fixture(scope="session")
def edge_set() -> np.ndarray:
    """600 genomes (600, 56) made only of bin-edge values and values in [0, 1e-3)."""
    rng = np.random.default_rng(7)
    genomes = rng.choice(EDGE_VALUES, (600, N_GENES))
    tiny = rng.random((600, N_GENES)) < 0.3
    genomes[tiny] = rng.random(int(tiny.sum())) * 1e-3
    return genomes
