"""Provides linkage references into MLflow: `RUN_ID` (a trial's best), `RUN_ID:CELL` or
`RUN_ID:B0,B1[,...]` (a repertoire cell by its flat index or its bin coordinates; of a SAIL
trial, a cell of its prediction map where its walked map has none), and the listing of a
repertoire's best cells with their physical checks."""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from linkevo.sim.errors import LinkevoError
from linkevo.sim.linkage.linkage_doc import to_document
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.artifacts import read_document
from linkevo.workers.store.tables import bin_columns

if TYPE_CHECKING:
    from linkevo.workers.store.runs import RunStore


class LinkageError(LinkevoError, ValueError):
    """A linkage reference that cannot be resolved: bad text, unknown run or cell."""


@dataclass(frozen=True)
class LinkageRef:
    """`RUN_ID` (the run's best linkage), `RUN_ID:CELL` (a repertoire cell by its flat
    index) or `RUN_ID:B0,B1[,...]` (by its bin coordinates, one per descriptor)."""

    run_id: str
    cell: int | None = None
    bins: tuple[int, ...] | None = None

    @classmethod
    def parse(cls, text: str) -> LinkageRef:
        """Returns the reference parsed from `RUN_ID[:CELL | :B0,B1,...]`."""
        run_id, sep, where = text.partition(":")
        parts = where.split(",")
        if not run_id or (sep and not all(p.isdigit() for p in parts)):
            raise LinkageError(
                f"{text!r}: expected RUN_ID, RUN_ID:CELL (a non-negative integer) or "
                "RUN_ID:B0,B1,... (bin coordinates, e.g. 12,40)"
            )
        if not sep:
            return cls(run_id)
        if len(parts) == 1:
            return cls(run_id, cell=int(parts[0]))
        return cls(run_id, bins=tuple(int(p) for p in parts))


@dataclass(frozen=True)
class SourceLinkage:
    """The linkage to build, with the source run's identity and tags."""

    run_id: str
    cell: int | None
    experiment_id: str
    approach: str
    fitness: str
    document: dict
    grid_id: str = ""
    predicted: bool = False
    """The cell is a SAIL trial's prediction map's, never walked (`workers.walk_sail`)."""


def load_source(store: RunStore, ref: LinkageRef) -> SourceLinkage:
    """Returns the linkage document a reference points at, with its run's tags.

    A cell's genome is turned into a document with `sim.linkage.linkage_doc.to_document` in the
    run's `mode` (param; default "paper").

    A cell that a SAIL trial's walked map lacks is looked up in its prediction map.

    Raises:
        LinkageError: unknown run, or a cell not in the repertoire (nor prediction map).
        NotFound: the run lacks the artefact (its best linkage or repertoire).
    """
    from linkevo.workers.store.runs import NotFound

    try:
        run = store.run(ref.run_id)
    except NotFound as exc:
        raise LinkageError(f"--linkage: no MLflow run with id {ref.run_id!r}") from exc
    tags = run.data.tags
    predicted = False
    with tempfile.TemporaryDirectory() as tmp:
        if ref.cell is None and ref.bins is None:
            path = store.download(ref.run_id, layout.BEST_JSON, Path(tmp))
            document, cell = read_document(path), None
        else:
            table = store.repertoire(ref.run_id, Path(tmp))
            try:
                cell, genome = _find_cell(table, ref)
            except LinkageError:
                sail = store.prediction_map(ref.run_id, Path(tmp) / "sail")
                if sail is None:
                    raise
                cell, genome = _find_cell(sail, ref, "walked map or its prediction map")
                predicted = True
            document = to_document(genome, run.data.params.get("mode", "paper"))
    return SourceLinkage(
        run_id=ref.run_id,
        cell=cell,
        experiment_id=run.info.experiment_id,
        approach=tags.get(layout.APPROACH, "unknown"),
        fitness=tags.get(layout.FITNESS, "unknown"),
        document=document,
        grid_id=tags.get(layout.GRID_ID, ""),
        predicted=predicted,
    )


def _find_cell(table, ref: LinkageRef, where: str = "repertoire") -> tuple[int, np.ndarray]:
    """Returns (flat cell, genome (56,)) of the repertoire row a cell reference names."""
    bins = bin_columns(table.columns)
    if ref.bins is not None:
        if len(ref.bins) != len(bins):
            raise LinkageError(
                f"{ref.run_id}:{','.join(map(str, ref.bins))}: the repertoire has "
                f"{len(bins)} descriptors, so give {len(bins)} bin coordinates"
            )
        hit = np.ones(len(table), dtype=bool)
        for column, value in zip(bins, ref.bins, strict=True):
            hit &= table[column].to_numpy() == value
        what = f"the cell at bins ({', '.join(map(str, ref.bins))})"
    else:
        hit = table["cell"].to_numpy() == ref.cell
        what = f"cell {ref.cell}"
    if not hit.any():
        raise LinkageError(
            f"{ref.run_id}: {what} is not in the {where} ({len(table)} filled cells); "
            f"list them with: linkevo pull {ref.run_id} --list"
        )
    row = table.iloc[int(np.flatnonzero(hit)[0])]
    return int(row["cell"]), np.asarray(row["genome"], dtype=float)


def list_cells(store: RunStore, run_id: str, top: int, mode: str, buildable: bool = False):
    """Returns the `top` lowest-loss cells of a run's repertoire with their physical checks.

    Args:
        buildable: keep only cells whose linkage passes `sim.linkage.physical`'s checks.

    Returns:
        A pandas table: cell, bins, loss, turns (fully), width and height (modules), min
        transmission angle (degrees), toggle passages, largest stretch (modules), buildable;
        ascending loss.
    """
    import pandas as pd

    from linkevo.sim import decode, simulate
    from linkevo.sim.linkage.physical import physical_checks

    with tempfile.TemporaryDirectory() as tmp:
        table = store.repertoire(run_id, Path(tmp))
    table = table.sort_values(["loss", "cell"], kind="stable").reset_index(drop=True)
    genomes = np.stack(table["genome"].to_numpy()).astype(float)
    batch = decode(genomes, mode)
    checks = physical_checks(batch, simulate(batch))
    bins = bin_columns(table.columns)
    out = pd.DataFrame(
        {
            "cell": table["cell"],
            "bins": [",".join(str(int(v)) for v in row) for row in table[bins].to_numpy()],
            "loss": table["loss"],
            "turns": checks.turns_fully,
            "width": checks.size_modules[:, 0],
            "height": checks.size_modules[:, 1],
            "min_transmission_deg": checks.min_transmission_deg,
            "toggles": checks.toggle_passages,
            "max_stretch": checks.max_stretch,
            "buildable": checks.buildable,
        }
    )
    if buildable:
        out = out[out["buildable"]]
    return out.head(top).reset_index(drop=True)
