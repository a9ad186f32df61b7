"""Provides the constants and scalarisation behind the reported scores (QD-score, hypervolume)."""

from __future__ import annotations

import numpy as np

from linkevo.sim.robot.walk_rows import WALKER_CM

QD_OFFSETS: dict[str, float] = {"Fp": 1000.0, "Fsl": 200.0, "Fw": 0.0}
"""QD-score offset per fitness: a cell adds max(offset - loss, 0).

F_p and F_sl: above the worst loss of 5,000 random genomes in either mode (F_p: 578 paper,
811 legacy; F_sl: 39 paper, 173 legacy), so the terms stay positive; one value per fitness
for every approach so scores compare. F_w: 0, so a cell adds the distance its leg walks
forwards on the worse floor without breaking and nothing else (the walking QD-score, in
cm; `sim.robot.walk_fitness`).
"""
HV_REFERENCES: dict[str, tuple[float, float]] = {
    "Fp2": (600.0, 600.0),
    "Fsl2": (200.0, 200.0),
    "Fw2": (0.0, 0.0),
}
"""NSGA-II hypervolume reference point per two-objective fitness (above the worst random
losses: Fp2 (330, 273) paper / (516, 435) legacy; Fsl2 (39, 39) / (184, 130)); for F_w2 the
area of (flat, carpet) distances dominated by legs that walk forwards on both (cm²)."""
WALKER_LOSS = -WALKER_CM
"""An F_w loss at or below this is a walker: 50 cm or more on both floors in 10 s, without
breaking (`sim.robot.walk_rows.WALKER_CM`)."""


def coverage(filled: int, n_cells: int) -> float:
    """Returns the filled fraction of a grid of `n_cells` cells."""
    return filled / n_cells


def qd_score(losses: np.ndarray, offset: float) -> float:
    """Returns the QD-score of the elites' (K,) losses: the sum of max(offset - loss, 0)."""
    return float(np.sum(np.maximum(offset - losses, 0.0)))


def scalar_loss(
    loss: np.ndarray, error: np.ndarray, angle_error: np.ndarray, fitness: str
) -> np.ndarray:
    """Returns the single-objective loss of each individual, from either variant.

    The two-objective variants add the penalty p = error + F_ae to both objectives, so the
    single-objective loss is recovered exactly: F_p = l0 + l1 - p (the D sums over step and
    lift points add up to D) and F_sl = 0.8 l0 + 0.2 l1 (the weights sum to 1).

    Args:
        loss: (N,) single-objective or (N, 2) two-objective losses.
        error: (N,) failed crank angles.
        angle_error: (N,) F_ae.
        fitness: "Fp", "Fsl" or "Fw" (or their two-objective names).

    Returns:
        (N,) float64 losses.
    """
    if loss.ndim == 1:
        return loss
    if fitness in ("Fw", "Fw2"):  # the worse floor
        return loss.max(axis=1)
    if fitness in ("Fp", "Fp2"):
        return loss[:, 0] + loss[:, 1] - error - angle_error
    if fitness in ("Fsl", "Fsl2"):
        return 0.8 * loss[:, 0] + 0.2 * loss[:, 1]
    raise ValueError(f"unknown fitness {fitness!r}; allowed: Fp, Fsl, Fw, Fp2, Fsl2, Fw2")
