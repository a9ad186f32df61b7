"""Provides F_p target point sets and the fitness names the kernels understand (spec §4)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from linkevo.sim.linkage.kernels import FP, FP2, FSL, FSL2
from linkevo.sim.study import PATH_FITNESSES, TARGETS

FITNESS_CODES: dict[str, int] = {"Fp": FP, "Fsl": FSL, "Fp2": FP2, "Fsl2": FSL2}
"""Kernel code of each fitness name."""
N_OBJECTIVES: dict[str, int] = {"Fp": 1, "Fsl": 1, "Fp2": 2, "Fsl2": 2}


@dataclass(frozen=True)
class Target:
    """F_p target points relative to the path centroid.

    Attributes:
        points: (P, 2) float64 target coordinates in LEGO modules.
        is_step: (P,) bool, True for "step" points (first objective of Fp2), False for
            "lift" points (second objective).
        name: a label for logs and documents.
    """

    points: np.ndarray
    is_step: np.ndarray
    name: str = "custom"

    def __post_init__(self) -> None:
        points = np.ascontiguousarray(self.points, dtype=np.float64)
        is_step = np.ascontiguousarray(self.is_step, dtype=np.bool_)
        if points.ndim != 2 or points.shape[1] != 2 or points.shape[0] == 0:
            raise ValueError(
                f"target points must have shape (P, 2) with P >= 1, got {points.shape}"
            )
        if not np.isfinite(points).all():
            raise ValueError("target points must be finite numbers")
        if is_step.shape != (points.shape[0],):
            raise ValueError(
                f"target is_step must have shape ({points.shape[0]},), got {is_step.shape}"
            )
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "is_step", is_step)

    @staticmethod
    def from_dict(doc: dict, name: str = "custom") -> Target:
        """Returns a target from `{"step": [[x, y], ...], "lift": [[x, y], ...]}`."""
        if not isinstance(doc, dict) or set(doc) - {"step", "lift", "name"} or "step" not in doc:
            found = sorted(doc) if isinstance(doc, dict) else type(doc).__name__
            raise ValueError(
                'a target file must be a JSON object {"step": [[x, y], ...], '
                f'"lift": [[x, y], ...]}}; got {found}'
            )
        step = np.asarray(doc["step"], dtype=np.float64).reshape(-1, 2)
        lift = np.asarray(doc.get("lift", []), dtype=np.float64).reshape(-1, 2)
        return Target(
            points=np.concatenate([step, lift]),
            is_step=np.r_[np.ones(len(step), bool), np.zeros(len(lift), bool)],
            name=str(doc.get("name", name)),
        )

    def to_dict(self) -> dict:
        """Returns the JSON-able form read by `from_dict`."""
        return {
            "name": self.name,
            "step": self.points[self.is_step].tolist(),
            "lift": self.points[~self.is_step].tolist(),
        }


def _laying_d(bottom_x: np.ndarray, bottom_y: float, arc_x: np.ndarray, arc_y: list[float]):
    points = np.concatenate(
        [np.c_[bottom_x, np.full(len(bottom_x), bottom_y)], np.c_[arc_x, arc_y]]
    )
    is_step = np.r_[np.ones(len(bottom_x), bool), np.zeros(len(arc_x), bool)]
    return points, is_step


_D16 = _laying_d(
    np.arange(-8.0, 9.0, 2.0),
    -1.73125,
    np.arange(-6.0, 7.0, 2.0),
    [1.26875, 2.26875, 2.76875, 2.96875, 2.76875, 2.26875, 1.26875],
)
_D24 = _laying_d(
    np.arange(-12.0, 13.0, 3.0),
    -1.303125,
    np.arange(-9.0, 10.0, 3.0),
    [1.196875, 1.696875, 1.946875, 2.046875, 1.946875, 1.696875, 1.196875],
)


def named_target(name: str = "D16") -> Target:
    """Returns a published target: "D16" (the paper's, default) or "D24" (flatter)."""
    table = {"D16": _D16, "D24": _D24}
    if name not in table:
        raise ValueError(f"unknown target {name!r}; allowed: {', '.join(TARGETS)} or a file")
    points, is_step = table[name]
    return Target(points=points.copy(), is_step=is_step.copy(), name=name)


def check_fitness(fitness: str) -> str:
    """Returns `fitness` if it is a known name, else raises ValueError naming the choices."""
    if fitness not in PATH_FITNESSES:
        raise ValueError(f"unknown fitness {fitness!r}; allowed: {', '.join(PATH_FITNESSES)}")
    return fitness
