"""Provides the Evaluation result of simulating and scoring a batch of genomes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

Mode = Literal["paper", "legacy"]
MODES: tuple[str, ...] = ("paper", "legacy")
Fitness = Literal["Fp", "Fsl", "Fp2", "Fsl2"]
FITNESSES: tuple[str, ...] = ("Fp", "Fsl", "Fp2", "Fsl2")


@dataclass(frozen=True)
class Evaluation:
    """What `sim.evaluate` gives back for N genomes simulated over A crank angles.

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
