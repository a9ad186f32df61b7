"""Provides `path_diversity`: how different the shapes of a set of foot paths are, one
number per repertoire or population."""

from __future__ import annotations

import numpy as np

DIVERSITY_PATHS = 100
"""Paths measured: the lowest-loss ones of a repertoire or population."""
POINT_RADIUS = 1e-3
"""A path whose RMS radius is below this (units; 8 micrometres) is a point (a foot that
does not move): it stays at the origin rather than blowing its rounding noise up."""


def normalised_paths(foot_x: np.ndarray, foot_y: np.ndarray) -> np.ndarray:
    """Returns each path (N, A, 2) centred on its centroid and divided by its RMS radius, so
    that only its shape is left (a path smaller than `POINT_RADIUS` stays at the origin).

    Args:
        foot_x, foot_y: (N, A) complete foot paths (no NaN).
    """
    xy = np.stack([foot_x, foot_y], axis=2).astype(np.float64)
    xy -= xy.mean(axis=1, keepdims=True)
    radius = np.sqrt((xy**2).sum(axis=2).mean(axis=1))[:, None, None]
    return np.divide(xy, radius, out=np.zeros_like(xy), where=radius > POINT_RADIUS)


def path_diversity(
    foot_x: np.ndarray, foot_y: np.ndarray, loss: np.ndarray, k: int = DIVERSITY_PATHS
) -> float:
    """Returns the mean pairwise shape distance between the k lowest-loss complete paths.

    Two paths' distance is the RMS distance between their normalised samples
    (`normalised_paths`), at the crank phase that brings them closest (a path's shape does
    not depend on where the turn starts): 0 for the same shape, about 1.4 for two unrelated
    ones, 2 at most. Duplicates count, so a population that has converged onto one shape
    scores near 0. NaN when fewer than two paths are complete.

    Args:
        foot_x, foot_y: (N, A) foot paths, NaN at failed crank angles.
        loss: (N,) single-objective losses (lower is better).
        k: how many of the best paths to compare.
    """
    complete = np.isfinite(foot_x).all(axis=1) & np.isfinite(foot_y).all(axis=1)
    complete &= np.isfinite(loss)
    rows = np.flatnonzero(complete)
    rows = rows[np.argsort(loss[rows], kind="stable")][:k]
    if rows.size < 2:
        return float("nan")
    paths = normalised_paths(foot_x[rows], foot_y[rows])  # (K, A, 2)
    n_angles = paths.shape[1]
    shifted = np.stack([np.roll(paths, -s, axis=1) for s in range(n_angles)], axis=1)
    total, pairs = 0.0, 0
    for i in range(len(paths) - 1):
        # (K - i - 1, A) squared distances of path i to each later path at each phase
        d2 = ((shifted[i + 1 :] - paths[i][None, None]) ** 2).sum(axis=3).mean(axis=2)
        total += float(np.sqrt(d2.min(axis=1)).sum())
        pairs += len(d2)
    return total / pairs
