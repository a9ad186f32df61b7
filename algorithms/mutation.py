"""Provides the batched self-adaptive mutation of spec §6 (paper and legacy modes)."""

from __future__ import annotations

import numpy as np

from linkevo.sim.linkage.genome import LENGTH_GENES, N_GENES

GENE_PROBABILITY = 0.2
"""Chance that a non-length gene mutates (paper) or that every gene is reset (legacy)."""
SIGMA_PROBABILITY = 0.2
"""Chance that a mutation strength is perturbed."""
SIGMA_NOISE = 0.1
"""Standard deviation of the perturbation of a mutation strength."""
_BELOW_ONE = np.nextafter(1.0, 0.0)


def check_initial_sigma(value: object) -> None:
    """Raises ValueError unless `value` is None or a number in [0, 1)."""
    ok = value is None or (
        isinstance(value, int | float) and not isinstance(value, bool) and 0.0 <= value < 1.0
    )
    if not ok:
        raise ValueError(f"initial_sigma must be in [0, 1) or None, got {value!r}")


def n_sigmas(mode: str) -> int:
    """Returns how many mutation strengths a genome carries: 1 (paper) or 2 (legacy)."""
    if mode == "paper":
        return 1
    if mode == "legacy":
        return 2
    raise ValueError(f"mode must be 'paper' or 'legacy', got {mode!r}")


def bounce_back(values: np.ndarray) -> np.ndarray:
    """Returns `values` folded into [0, 1) by bounce-back (x >= 1 -> 2 - x, x < 0 -> -x).

    The fold is periodic with period 2, so one `x mod 2` does the repeated reflection. A value
    that lands exactly on 1.0 (a fixed point of the published rule) becomes the largest
    float below 1.

    Args:
        values: any shape.

    Returns:
        An array of the same shape in [0, 1).
    """
    folded = np.multiply(values, 0.5)
    folded -= np.floor(folded)
    folded *= 2.0  # x mod 2, exact for x in [0, 1); in place: this runs on (B, 56) arrays
    np.subtract(2.0, folded, out=folded, where=folded >= 1.0)
    return np.minimum(folded, _BELOW_ONE, out=folded)


def initial_sigma(
    rng: np.random.Generator, n: int, mode: str, value: float | None = None
) -> np.ndarray:
    """Returns the mutation strengths of `n` new random genomes, shape (n, S).

    Args:
        rng: the random source.
        n: number of genomes.
        mode: "paper" (S = 1) or "legacy" (S = 2).
        value: a fixed strength for all; None draws each uniformly in [0, 1), like any
            other gene (the paper encodes sigma "along with the genome").
    """
    shape = (n, n_sigmas(mode))
    if value is None:
        return rng.random(shape)
    if not 0.0 <= value < 1.0:
        raise ValueError(f"initial sigma must be in [0, 1), got {value!r}")
    return np.full(shape, float(value))


def mutate(
    genomes: np.ndarray, sigma: np.ndarray, rng: np.random.Generator, mode: str
) -> tuple[np.ndarray, np.ndarray]:
    """Returns mutated copies of `genomes` and their mutated strengths.

    paper: each sigma gets N(0, 0.1) with probability 0.2 and is bounced back; then every
    length gene, and each other gene with probability 0.2, gets N(0, sigma) added (the new
    sigma); everything is bounced back into [0, 1).

    legacy: both sigmas (structure, length) are perturbed like the paper's; then, with
    probability 0.2 all 56 genes, else only the 15 length genes, are replaced by
    N(0, sigma) folded into [0, 1), using sigma_length for length genes and
    sigma_structure for the others.

    Args:
        genomes: parents, shape (N, 56), in [0, 1).
        sigma: parents' strengths, shape (N, 1) (paper) or (N, 2) (legacy).
        rng: the random source (draws happen in a fixed order, so a seed reproduces).
        mode: "paper" or "legacy".

    Returns:
        (children (N, 56), children's sigma (N, S)), both in [0, 1).
    """
    n = genomes.shape[0]
    if sigma.shape != (n, n_sigmas(mode)):
        raise ValueError(f"sigma must have shape {(n, n_sigmas(mode))}, got {sigma.shape}")
    perturb = rng.random(sigma.shape) < SIGMA_PROBABILITY
    new_sigma = bounce_back(sigma + perturb * rng.normal(0.0, SIGMA_NOISE, sigma.shape))
    is_length = np.zeros(N_GENES, dtype=bool)
    is_length[LENGTH_GENES] = True
    noise = rng.standard_normal((n, N_GENES))
    if mode == "paper":
        mask = (rng.random((n, N_GENES)) < GENE_PROBABILITY) | is_length
        return bounce_back(genomes + mask * noise * new_sigma), new_sigma
    reset_all = rng.random(n) < GENE_PROBABILITY
    mask = reset_all[:, None] | is_length[None, :]
    per_gene_sigma = np.where(is_length[None, :], new_sigma[:, 1:2], new_sigma[:, 0:1])
    children = np.where(mask, bounce_back(noise * per_gene_sigma), genomes)
    return children, new_sigma
