"""Provides LinkageBatch and `decode`: genomes to linkage topology at crank angle 0; and
`with_lengths`: a batch with other beam lengths."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from linkevo.sim.linkage import kernels
from linkevo.sim.linkage.genome import MAX_BEAMS, N_NODES, validate_genomes
from linkevo.sim.study import MODES

NODE_KINDS = ("motor", "static", "crank", "triangle", "extension")
BEAM_KINDS = ("crank", "triangle", "extension")


@dataclass(frozen=True)
class LinkageBatch:
    """N decoded linkages.

    Attributes:
        mode: "paper" or "legacy".
        node_int: (N, 12, 4) int64 per node [kind, a, c, direction]; triangle a, c are
            anchors A, C; extension a is the parent beam and c the inverted flag.
        node_float: (N, 12, 5) float64 per node; triangle [l1, l2, backup angle,
            l1 cos(backup), l1 sin(backup) (0, 0 unless l1 == l2)]; extension [length, 0...];
            static [x, y, 0...];
            crank tip [crank length, 0...].
        beam_int: (N, 15, 6) int64 per beam [start, end, kind, parent, root, inversions],
            -1 where absent (see `sim.linkage.kernels.decode_and_simulate`).
        beam_length: (N, 15) float64, 0 where absent.
        n_beams: (N,) int64.
        positions0: (N, 12, 2) float64 node positions at crank angle 0.
    """

    mode: str
    node_int: np.ndarray
    node_float: np.ndarray
    beam_int: np.ndarray
    beam_length: np.ndarray
    n_beams: np.ndarray
    positions0: np.ndarray

    def __len__(self) -> int:
        return int(self.n_beams.shape[0])

    @property
    def node_kind(self) -> np.ndarray:
        """(N, 12) int64 node kinds (indices into NODE_KINDS)."""
        return self.node_int[:, :, 0]

    @property
    def beam_start(self) -> np.ndarray:
        """(N, 15) int64 start node of each beam, -1 where absent."""
        return self.beam_int[:, :, 0]

    @property
    def beam_end(self) -> np.ndarray:
        """(N, 15) int64 end node of each beam, -1 where absent."""
        return self.beam_int[:, :, 1]

    @property
    def beam_kind(self) -> np.ndarray:
        """(N, 15) int64 beam kinds (indices into BEAM_KINDS), -1 where absent."""
        return self.beam_int[:, :, 2]


def check_mode(mode: str) -> bool:
    """Returns True for legacy mode; raises ValueError naming the allowed modes."""
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}; allowed: {', '.join(MODES)}")
    return mode == "legacy"


def decode(genomes: np.ndarray, mode: str = "paper") -> LinkageBatch:
    """Returns the decoded linkages of genomes (N, 56) (spec §1–2)."""
    legacy = check_mode(mode)
    genomes = validate_genomes(genomes)
    n = genomes.shape[0]
    batch = LinkageBatch(
        mode=mode,
        node_int=np.empty((n, N_NODES, 4), np.int64),
        node_float=np.empty((n, N_NODES, 5)),
        beam_int=np.empty((n, MAX_BEAMS, 6), np.int64),
        beam_length=np.empty((n, MAX_BEAMS)),
        n_beams=np.empty(n, np.int64),
        positions0=np.empty((n, N_NODES, 2)),
    )
    kernels.decode_batch(
        genomes,
        legacy,
        batch.node_int,
        batch.node_float,
        batch.beam_int,
        batch.beam_length,
        batch.n_beams,
        batch.positions0,
    )
    return batch


def with_lengths(batch: LinkageBatch, lengths: np.ndarray) -> LinkageBatch:
    """Returns the batch (N linkages) with beam lengths (N, 15) put into its node
    parameters: the crank's, each extension's length, each triangle's l1 and l2 and its
    backup point (which exists only where l1 == l2, as `sim.linkage.decoding` writes it)."""
    n = len(batch)
    present = np.arange(lengths.shape[1])[None, :] < batch.n_beams[:, None]
    lengths = np.where(present, lengths, 0.0)
    ends = np.where(present, batch.beam_int[:, :, 1], -1)
    # each node's first and second beam (those that place it), -1 where none
    first = np.full((n, batch.node_int.shape[1]), -1)
    second = first.copy()
    for b in range(lengths.shape[1] - 1, -1, -1):  # last first, so the earliest stays first
        rows = np.flatnonzero(ends[:, b] >= 0)
        node = ends[rows, b]
        second[rows, node] = first[rows, node]
        first[rows, node] = b
    node_float = batch.node_float.copy()
    rows = np.arange(n)
    kind = batch.node_int[:, :, 0]
    for j in range(node_float.shape[1]):
        one = (
            (kind[:, j] == NODE_KINDS.index("crank"))
            | (kind[:, j] == NODE_KINDS.index("extension"))
        ) & (first[:, j] >= 0)
        node_float[one, j, 0] = lengths[rows[one], first[one, j]]
        tri = (kind[:, j] == NODE_KINDS.index("triangle")) & (second[:, j] >= 0)
        l1 = lengths[rows[tri], first[tri, j]]
        l2 = lengths[rows[tri], second[tri, j]]
        angle = node_float[tri, j, 2]
        node_float[tri, j, 0] = l1
        node_float[tri, j, 1] = l2
        node_float[tri, j, 3] = np.where(l1 == l2, l1 * np.cos(angle), 0.0)
        node_float[tri, j, 4] = np.where(l1 == l2, l1 * np.sin(angle), 0.0)
    return dataclasses.replace(batch, node_float=node_float, beam_length=lengths)
