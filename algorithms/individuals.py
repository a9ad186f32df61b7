"""Provides Individuals: the genomes and evaluation results a population or archive keeps."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from linkevo.sim.linkage.genome import N_GENES


@dataclass(frozen=True)
class Individuals:
    """N evaluated genomes, row-aligned.

    Attributes:
        genome: (N, 56) float64 in [0, 1).
        sigma: (N, S) float64 mutation strengths (S = 1 paper, 2 legacy).
        loss: (N,) or (N, 2) float64 losses to minimise.
        error: (N,) int64 failed crank angles.
        angle_error: (N,) float64 F_ae.
        desc: (N, D) float64 continuous descriptors.
        foot_x: (N, A) float64 foot path x, NaN at failed angles.
        foot_y: (N, A) float64 foot path y, NaN at failed angles.
    """

    genome: np.ndarray
    sigma: np.ndarray
    loss: np.ndarray
    error: np.ndarray
    angle_error: np.ndarray
    desc: np.ndarray
    foot_x: np.ndarray
    foot_y: np.ndarray

    def __len__(self) -> int:
        return int(self.genome.shape[0])

    def take(self, index: np.ndarray) -> Individuals:
        """Returns the rows `index` (any numpy index over N)."""
        return Individuals(**{f.name: getattr(self, f.name)[index] for f in fields(self)})

    @staticmethod
    def concat(parts: list[Individuals]) -> Individuals:
        """Returns the row-wise concatenation of `parts`, in order."""
        return Individuals(
            **{
                f.name: np.concatenate([getattr(p, f.name) for p in parts], axis=0)
                for f in fields(Individuals)
            }
        )

    def to_state(self, prefix: str) -> dict[str, np.ndarray]:
        """Returns the arrays keyed `<prefix>.<field>`, for an npz state dict."""
        return {f"{prefix}.{f.name}": getattr(self, f.name) for f in fields(self)}

    @staticmethod
    def from_state(state: dict[str, np.ndarray], prefix: str) -> Individuals:
        """Returns the Individuals stored by `to_state(prefix)`.

        Raises:
            KeyError: a field is missing.
            ValueError: naming the field, when its dtype, shape or values are not those
                `to_state` writes (real numbers, one row per genome, genes in [0, 1),
                finite losses, mutation strengths and descriptors, error counts >= 0,
                foot coordinates finite or NaN at failed angles).
        """
        arrays = {f.name: np.asarray(state[f"{prefix}.{f.name}"]) for f in fields(Individuals)}
        n = arrays["genome"].shape[0] if arrays["genome"].ndim == 2 else -1

        def bad(name: str, what: str) -> ValueError:
            array = arrays[name]
            return ValueError(f"{prefix}.{name} ({array.dtype}, shape {array.shape}): {what}")

        for name, array in arrays.items():
            kind = "i" if name == "error" else "f"
            if array.dtype.kind != kind:
                raise bad(name, f"allowed: {'integers' if kind == 'i' else 'real numbers'}")
            if array.ndim == 0 or array.shape[0] != n:
                raise bad(name, f"allowed: one row per genome ({n})")
        genome = arrays["genome"]
        if genome.shape[1] != N_GENES or not ((genome >= 0) & (genome < 1)).all():
            raise bad("genome", f"allowed: ({n}, {N_GENES}) genes in [0, 1)")
        if not np.isfinite(arrays["loss"]).all():
            raise bad("loss", "allowed: finite losses")
        if (arrays["error"] < 0).any():
            raise bad("error", "allowed: failed-angle counts >= 0")
        sigma = arrays["sigma"]
        if not (np.isfinite(sigma) & (sigma >= 0)).all():
            raise bad("sigma", "allowed: finite mutation strengths >= 0")
        if not np.isfinite(arrays["desc"]).all():
            raise bad("desc", "allowed: finite descriptors")
        for name in ("foot_x", "foot_y"):
            if np.isinf(arrays[name]).any():
                raise bad(name, "allowed: finite coordinates, NaN at failed angles")
        return Individuals(**arrays)
