"""Provides the genome layout, random genomes and genome validation (spec §1)."""

from __future__ import annotations

import numba
import numpy as np

from linkevo.sim.errors import LinkevoError

N_GENES = 56
"""Genes per genome."""
N_STATIC = 3
"""Static nodes (robot connections besides the motor)."""
CRANK_GENE = 6
"""Index of the crank-length gene."""
N_BLOCKS = 7
"""Added nodes, one seven-gene block each."""
BLOCK_SIZE = 7
FIRST_BLOCK = 7
N_NODES = 1 + N_STATIC + 1 + N_BLOCKS
"""Motor, static nodes, crank tip, added nodes: 12."""
MAX_BEAMS = 1 + 2 * N_BLOCKS
"""Crank plus two beams per triangle: 15."""
LENGTH_GENES = np.array(
    [CRANK_GENE] + [FIRST_BLOCK + BLOCK_SIZE * i + k for i in range(N_BLOCKS) for k in (5, 6)],
    dtype=np.int64,
)
"""The 15 length genes (crank, then l1 and l2 of each block), shape (15,)."""


class GenomeError(LinkevoError, ValueError):
    """A genome array that cannot be decoded."""


def random_genomes(rng: np.random.Generator, n: int) -> np.ndarray:
    """Returns `n` uniform random genomes, shape (n, 56), float64 in [0, 1)."""
    if n < 0:
        raise GenomeError(f"number of genomes must be >= 0, got {n}")
    return rng.random((n, N_GENES))


@numba.njit(cache=True, nogil=True)
def first_outside_unit_interval(values: np.ndarray) -> int:
    """Returns the index of the first value (1-D) not in [0, 1) (NaN included), or -1.

    A trial checks every batch, so the common all-good case is one branch-free
    (vectorised) pass; only a bad batch is searched again for the first bad value.
    """
    inside = 0
    for i in range(values.shape[0]):
        inside += (values[i] >= 0.0) & (values[i] < 1.0)  # NaN fails both comparisons
    if inside == values.shape[0]:
        return -1
    for i in range(values.shape[0]):
        if not (values[i] >= 0.0 and values[i] < 1.0):
            return i
    return -1


def validate_genomes(genomes: object) -> np.ndarray:
    """Returns the genomes as a C-contiguous float64 array of shape (N, 56).

    Raises:
        GenomeError: naming the first bad row and value when the input is not a
            2-D real array with 56 columns, or holds a value that is not finite
            or outside [0, 1).
    """
    arr = np.asarray(genomes)
    if arr.ndim != 2 or arr.shape[1] != N_GENES:
        raise GenomeError(f"genomes must have shape (N, {N_GENES}), got {arr.shape}")
    if arr.dtype.kind not in "fiu":
        raise GenomeError(f"genomes must be a real float array, got dtype {arr.dtype}")
    arr = np.ascontiguousarray(arr, dtype=np.float64)
    bad = first_outside_unit_interval(arr.reshape(-1))
    if bad >= 0:
        row, col = divmod(bad, N_GENES)
        raise GenomeError(
            f"genome row {row}, gene {col} is {float(arr[row, col])!r}: "
            "every gene must be a finite number in [0, 1)"
        )
    return arr
