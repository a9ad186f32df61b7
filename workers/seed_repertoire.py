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
from linkevo.workers.store.tables import ArtefactError, read_repertoire, read_walk_map

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
    """Downloads the run's repertoire and walk map into `folder` once (a copy there that
    does not read back whole, a damaged or cut one, is fetched again); returns it.

    Raises:
        SeedError: the run has no repertoire or no walk map.
        ArtefactError: the run's own repertoire or walk map is damaged.
    """
    folder.mkdir(parents=True, exist_ok=True)
    for name, read in ((layout.REPERTOIRE, _repertoire), (layout.WALK_MAP, _walk_map)):
        if (folder / name).exists():
            try:
                read(folder, run_id)
                continue
            except ArtefactError:
                (folder / name).unlink()
        try:
            store.download(run_id, name, folder)
        except NotFound as exc:
            raise SeedError(
                f"seed_from {run_id!r} has no {name}: a warm start needs a MAP-Elites trial "
                f"and its walk map (`linkevo walkmap {run_id}` makes one)"
            ) from exc
        read(folder, run_id)
    return folder


def _repertoire(folder: Path, run_id: str) -> pd.DataFrame:
    return read_repertoire(folder / layout.REPERTOIRE, run_id, layout.REPERTOIRE)


def _walk_map(folder: Path, run_id: str) -> pd.DataFrame:
    return read_walk_map(folder / layout.WALK_MAP, run_id)


def read_seed(folder: Path, run_id: str = "seed_from") -> Seed:
    """Returns the warm start `fetch_seed` left in `folder`: the cells walked as LEGO
    legs on both floors, in ascending cell order.

    Raises:
        ArtefactError: a copy that does not read back whole (named with `run_id`).
    """
    repertoire = _repertoire(folder, run_id)
    walks = _walk_map(folder, run_id)
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
