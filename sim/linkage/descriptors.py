"""Provides the MAP-Elites descriptor spaces and the published binning (spec §5)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DescriptorSpace:
    """A grid over continuous descriptor values.

    Attributes:
        names: one name per dimension.
        resolution: bins per dimension (R).
        step: bin width per dimension, shape (D,).
    """

    names: tuple[str, ...]
    resolution: int
    step: tuple[float, ...]

    @property
    def dims(self) -> int:
        """Number of dimensions D."""
        return len(self.names)

    @property
    def n_cells(self) -> int:
        """Number of cells, R ** D."""
        return self.resolution**self.dims

    @property
    def shape(self) -> tuple[int, ...]:
        """Grid shape, (R,) * D."""
        return (self.resolution,) * self.dims


DESCRIPTOR_SPACES: dict[str, DescriptorSpace] = {
    "MAP-WH": DescriptorSpace(("height", "width"), 100, (1.0, 1.0)),
    "MAP-LIS": DescriptorSpace(("mean_beam_length", "lift"), 100, (0.1, 0.5)),
    "MAP-ST": DescriptorSpace(
        ("mean_beam_length", "depth", "drive_size", "moving_share"), 10, (1.0, 1.0, 1.0, 1.0)
    ),
    "MAP-AU": DescriptorSpace(("z0", "z1", "z2", "z3"), 10, (0.1, 0.1, 0.1, 0.1)),
}
"""Every MAP-Elites approach's space; MAP-AU's values come from the AURORA encoder."""
COVERAGE_SPACES: tuple[str, ...] = ("MAP-WH", "MAP-LIS", "MAP-ST")
"""The published grids whose descriptors `sim.linkage.evaluating` computes: the ones on which an
approach without its own grid (EA, NSGA-II, RANDOM) is measured."""


def check_coverage_space(name: object) -> None:
    """Raises ValueError unless `name` is one of `COVERAGE_SPACES`."""
    if name not in COVERAGE_SPACES:
        raise ValueError(f"unknown coverage_space {name!r}; allowed: {', '.join(COVERAGE_SPACES)}")


def bin_descriptors(values: np.ndarray, space: DescriptorSpace) -> np.ndarray:
    """Returns the published bins `#{i in 1..R-1 : v > i*step}` of values (N, D), int64."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2 or values.shape[1] != space.dims:
        raise ValueError(f"descriptor values must have shape (N, {space.dims}), got {values.shape}")
    bins = np.empty(values.shape, dtype=np.int64)
    i = np.arange(1, space.resolution)
    for d, step in enumerate(space.step):
        bins[:, d] = np.searchsorted(i * step, values[:, d], side="left")
    return bins


def cell_index(bins: np.ndarray, space: DescriptorSpace) -> np.ndarray:
    """Returns the flat cell index (N,) int64 of bins (N, D) in C order."""
    return np.ravel_multi_index(tuple(np.asarray(bins).T), space.shape).astype(np.int64)
