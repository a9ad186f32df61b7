"""Provides a walking trial's warm start (grid key `seed_from`): an earlier MAP-Elites
trial's repertoire and walk map as the walking trial's first batch.

The first batch is every cell of the earlier repertoire whose LEGO leg its walk map walked
on both floors: each is told with its walk-map rows, so it enters the archive as it walked
and costs no walk (`walks_reused` in the metrics). Cells the walk map did not walk (or
walked as evolved) are left out: a warm start continues a map towards walking, it does
not walk it anew. A walk-map walk lasts 10 s and a search walk `SEARCH_SECONDS`; losses
are per 10 s either way (`sim.robot.walk_rows.credited_cm`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.sim.errors import LinkevoError
from linkevo.sim.robot.walk_rows import LEGO_BUILD, WALK_ORDER, Status
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.runs import NotFound, RunStore

SEED_DIR = "seed"
"""The folder, in a trial's folder, holding its warm start's repertoire and walk map."""


class SeedError(LinkevoError, ValueError):
    """A warm start that cannot be made; the message says what would do."""


@dataclass(frozen=True)
class Seed:
    """A warm start: genomes (K, 56) and each one's walk-map row per floor."""

    genomes: np.ndarray
    rows: list[dict[str, dict]]

    def __len__(self) -> int:
        return len(self.genomes)


def fetch_seed(store: RunStore, run_id: str, folder: Path) -> Path:
    """Downloads the run's repertoire and walk map into `folder` (once); returns it.

    Raises:
        SeedError: the run has no repertoire or no walk map.
    """
    folder.mkdir(parents=True, exist_ok=True)
    for name in (layout.REPERTOIRE, layout.WALK_MAP):
        if (folder / name).exists():
            continue
        try:
            store.download(run_id, name, folder)
        except NotFound as exc:
            raise SeedError(
                f"seed_from {run_id!r} has no {name}: a warm start needs a MAP-Elites trial "
                f"and its walk map (`linkevo walkmap {run_id}` makes one)"
            ) from exc
    return folder


def read_seed(folder: Path) -> Seed:
    """Returns the warm start `fetch_seed` left in `folder`: the cells walked as LEGO
    legs on both floors, in ascending cell order."""
    repertoire = pd.read_parquet(folder / layout.REPERTOIRE)
    walks = pd.read_parquet(folder / layout.WALK_MAP)
    walks = walks[
        (walks["leg"] == LEGO_BUILD) & walks["status"].isin([Status.WALKED, Status.NOT_WALKED])
    ]
    by_cell = {
        int(cell): part
        for cell, part in walks.groupby("cell")
        if set(part["floor"]) >= set(WALK_ORDER)
    }
    genomes, rows = [], []
    for cell, genome in zip(repertoire["cell"], repertoire["genome"], strict=True):
        part = by_cell.get(int(cell))
        if part is None:
            continue
        genomes.append(np.asarray(genome, dtype=np.float64))
        rows.append({r["floor"]: {**r, "cell": -1} for r in part.to_dict("records")})
    return Seed(np.array(genomes).reshape(-1, 56), rows)
