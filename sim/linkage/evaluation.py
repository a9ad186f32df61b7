"""Provides the Evaluation result of simulating and scoring a batch of genomes."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from linkevo.sim.linkage.descriptors import COVERAGE_SPACES, DESCRIPTOR_SPACES

DESCRIPTOR_WIDTHS: dict[str, int] = {name: DESCRIPTOR_SPACES[name].dims for name in COVERAGE_SPACES}
"""Columns of each descriptor array `sim.linkage.evaluating` computes, by approach."""
ALIGNMENT = 64
"""Byte alignment of each array laid out in a shared buffer (a cache line)."""


def field_shapes(
    n: int, n_angles: int, n_objectives: int
) -> list[tuple[str, tuple[int, ...], type]]:
    """Returns (name, shape, dtype) of every Evaluation array for n genomes, in layout order.

    Descriptor arrays are named after their approach ("MAP-WH", ...).
    """
    loss_shape = (n,) if n_objectives == 1 else (n, n_objectives)
    return [
        ("loss", loss_shape, np.float64),
        ("error", (n,), np.int64),
        ("angle_error", (n,), np.float64),
        ("foot", (n,), np.int64),
        ("foot_x", (n, n_angles), np.float64),
        ("foot_y", (n, n_angles), np.float64),
        *((name, (n, width), np.float64) for name, width in DESCRIPTOR_WIDTHS.items()),
        ("valid", (n, n_angles), np.bool_),
    ]


def evaluation_bytes(n: int, n_angles: int) -> int:
    """Returns the bytes n genomes (N, 56) and their Evaluation at n_angles take (the
    kernel's own scratch is small beside them; measured: 5,000 genomes at 400 angles
    raise the peak memory by 33 MB against 37 MB here)."""
    per_genome = 56 * 8 + sum(
        int(np.prod(shape)) * np.dtype(dtype).itemsize
        for _, shape, dtype in field_shapes(1, n_angles, 1)
    )
    return n * per_genome


def _aligned(nbytes: int) -> int:
    return -(-nbytes // ALIGNMENT) * ALIGNMENT


@dataclass(frozen=True)
class Evaluation:
    """What `sim.linkage.evaluating` gives back for N genomes simulated over A crank angles.

    Attributes:
        loss: (N,) for Fp/Fsl, (N, 2) for Fp2/Fsl2; losses to minimise, always finite.
        error: (N,) int64, the number of failed crank angles (0..A-1).
        angle_error: (N,) float64, F_ae (paper: a count; legacy: distance-weighted).
        valid: (N, A) bool, True where the crank angle assembled.
        foot: (N,) int64, index of the foot node.
        foot_x: (N, A) float64 foot path x, NaN at failed angles.
        foot_y: (N, A) float64 foot path y, NaN at failed angles.
        descriptors: approach name ("MAP-WH", "MAP-LIS", "MAP-ST") -> (N, D) float64
            continuous descriptor values, on the scale the published binning expects.
    """

    loss: np.ndarray
    error: np.ndarray
    angle_error: np.ndarray
    valid: np.ndarray
    foot: np.ndarray
    foot_x: np.ndarray
    foot_y: np.ndarray
    descriptors: dict[str, np.ndarray]

    @staticmethod
    def nbytes_for(n: int, n_angles: int, n_objectives: int) -> int:
        """Returns the bytes `Evaluation.empty(..., buffer=...)` lays out for n genomes."""
        return sum(
            _aligned(math.prod(shape) * np.dtype(dtype).itemsize)
            for _, shape, dtype in field_shapes(n, n_angles, n_objectives)
        )

    @staticmethod
    def empty(
        n: int, n_angles: int, n_objectives: int, buffer: object = None, offset: int = 0
    ) -> Evaluation:
        """Returns an uninitialised Evaluation of n genomes, for `sim.evaluate(out=...)`.

        With `buffer` (any writable buffer, e.g. an mmap of at least `offset +
        nbytes_for(...)` bytes) the arrays are views laid out in it from `offset`, each on
        a 64-byte boundary; otherwise they are fresh arrays.
        """
        arrays = {}
        for name, shape, dtype in field_shapes(n, n_angles, n_objectives):
            if buffer is None:
                arrays[name] = np.empty(shape, dtype)
                continue
            arrays[name] = np.ndarray(shape, dtype, buffer, offset)
            offset += _aligned(math.prod(shape) * np.dtype(dtype).itemsize)
        descriptors = {name: arrays.pop(name) for name in DESCRIPTOR_WIDTHS}
        return Evaluation(**arrays, descriptors=descriptors)

    def arrays(self) -> dict[str, np.ndarray]:
        """Returns every array by its `field_shapes` name (descriptors by approach)."""
        flat = {k: v for k, v in vars(self).items() if k != "descriptors"}
        return {**flat, **self.descriptors}

    def __len__(self) -> int:
        return int(self.error.shape[0])

    def take(self, index: np.ndarray) -> Evaluation:
        """Returns the evaluation of the rows `index` (any numpy index over N)."""
        return Evaluation(
            loss=self.loss[index],
            error=self.error[index],
            angle_error=self.angle_error[index],
            valid=self.valid[index],
            foot=self.foot[index],
            foot_x=self.foot_x[index],
            foot_y=self.foot_y[index],
            descriptors={k: v[index] for k, v in self.descriptors.items()},
        )

    @staticmethod
    def concat(parts: list[Evaluation]) -> Evaluation:
        """Returns the row-wise concatenation of `parts`, in order."""
        if not parts:
            raise ValueError("concat needs at least one Evaluation")

        def cat(name: str) -> np.ndarray:
            return np.concatenate([getattr(p, name) for p in parts], axis=0)

        return Evaluation(
            loss=cat("loss"),
            error=cat("error"),
            angle_error=cat("angle_error"),
            valid=cat("valid"),
            foot=cat("foot"),
            foot_x=cat("foot_x"),
            foot_y=cat("foot_y"),
            descriptors={
                k: np.concatenate([p.descriptors[k] for p in parts], axis=0)
                for k in parts[0].descriptors
            },
        )
