"""Provides MAP-Elites on a descriptor grid (MAP-WH, MAP-LIS, MAP-ST; base of MAP-AU)."""

from __future__ import annotations

import numpy as np

from linkevo.algorithms.archive import GridArchive
from linkevo.algorithms.common_grid import COMMON_SPACE
from linkevo.algorithms.individuals import Individuals
from linkevo.algorithms.optimizer import BaseOptimizer
from linkevo.sim.linkage.descriptors import DESCRIPTOR_SPACES, DescriptorSpace
from linkevo.sim.linkage.evaluation import Evaluation


class MapElites(BaseOptimizer):
    """Each iteration: B parents drawn uniformly (with replacement) from the repertoire are
    mutated; a child takes its cell when the cell is empty or its loss is lower.

    Extension points for learned descriptors (AURORA): override `descriptors_of` to compute
    descriptors from the evaluation (e.g. an encoder of the foot paths), pass `space`, and
    call `reindex` after the descriptor function changes.

    Args:
        approach: "MAP-WH", "MAP-LIS", "MAP-ST" (or a subclass's name such as "MAP-AU").
        space: the grid; None takes `sim.linkage.descriptors.DESCRIPTOR_SPACES[approach]`.
        **kwargs: as `BaseOptimizer`.
    """

    def __init__(
        self, *, approach: str, space: DescriptorSpace | None = None, **kwargs: object
    ) -> None:
        super().__init__(**kwargs)  # type: ignore[arg-type]
        if space is None:
            if approach not in DESCRIPTOR_SPACES:
                raise ValueError(
                    f"unknown MAP-Elites approach {approach!r}; "
                    f"allowed: {', '.join(DESCRIPTOR_SPACES)}"
                )
            space = DESCRIPTOR_SPACES[approach]
        self.approach = approach
        self._archive = GridArchive(space=space)

    @property
    def archive(self) -> GridArchive:
        """The repertoire."""
        return self._archive

    def descriptors_of(self, genomes: np.ndarray, evaluation: Evaluation) -> np.ndarray:
        """Returns the published descriptors (B, D) of this approach from the evaluation."""
        return evaluation.descriptors[self.approach]

    def bar(self, genomes: np.ndarray, evaluation: Evaluation) -> np.ndarray:
        """Returns (B,) the loss each genome must beat to enter its cell, of the archive
        and of the common grid (inf where either is empty): at or above it, it changes
        neither the repertoire nor any metric (`Optimizer.bar`)."""
        own = self._archive.incumbents(self.descriptors_of(genomes, evaluation))
        common = self._common.incumbents(evaluation.descriptors[COMMON_SPACE])
        return np.minimum(own, common)

    def reindex(self, desc: np.ndarray) -> int:
        """Re-inserts every elite under new descriptors; returns how many were dropped.

        Args:
            desc: (K, D) new descriptors of `archive.elites`, in that order.
        """
        return self._archive.reindex(desc)

    def _parents(self) -> tuple[np.ndarray, np.ndarray]:
        if not len(self._archive):
            raise RuntimeError("the repertoire is empty: no batch had a finite loss")
        pick = self._rng.integers(0, len(self._archive), size=self.batch_size)
        parents = self._archive.columns("genome", "sigma", rows=pick)
        return parents["genome"], parents["sigma"]

    def _survive(self, batch: Individuals, *, initial: bool) -> None:
        self._archive.add(batch)

    def _kept(self) -> Individuals | None:
        return self._archive.elites

    def _summary(self) -> dict[str, float]:
        loss = self._archive.losses()
        if loss.size == 0:
            loss = np.full(1, np.nan)
        return {
            "mean_loss": float(np.mean(loss)),
            "coverage": self._archive.coverage(),
            "qd_score": self._archive.qd_score(self.qd_offset),
            **self._walkers(loss),
        }

    def _columns(self) -> dict[str, np.ndarray]:
        elites = self._archive.elites
        assert elites is not None
        bins = self._archive.bins(elites.desc)
        return {"cell": self._archive.cells} | {
            f"bin_{d}": bins[:, d] for d in range(bins.shape[1])
        }

    def _state(self) -> dict[str, np.ndarray]:
        return self._archive.state_dict()

    def _load_state(self, state: dict[str, np.ndarray]) -> None:
        self._archive.load_state_dict(state)
