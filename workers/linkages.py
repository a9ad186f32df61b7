"""Provides linkage references into MLflow: `RUN_ID` (a trial's best) or `RUN_ID:CELL`."""

from __future__ import annotations

import json
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mlflow.tracking import MlflowClient


class LinkageError(ValueError):
    """A linkage reference that cannot be resolved: bad text, unknown run or cell."""


@dataclass(frozen=True)
class LinkageRef:
    """`RUN_ID` (the run's best linkage) or `RUN_ID:CELL` (one repertoire cell)."""

    run_id: str
    cell: int | None = None

    @classmethod
    def parse(cls, text: str) -> LinkageRef:
        """Returns the reference parsed from `RUN_ID[:CELL]`."""
        run_id, sep, cell = text.partition(":")
        if not run_id or (sep and not cell.isdigit()):
            raise LinkageError(
                f"--linkage {text!r}: expected RUN_ID or RUN_ID:CELL "
                "with CELL a non-negative integer"
            )
        return cls(run_id, int(cell) if sep else None)


@dataclass(frozen=True)
class SourceLinkage:
    """The linkage to build, with the source run's identity and tags."""

    run_id: str
    cell: int | None
    experiment_id: str
    approach: str
    fitness: str
    document: dict


def _download(client: MlflowClient, run_id: str, name: str, into: Path) -> Path:
    from mlflow.exceptions import MlflowException

    try:
        return Path(client.download_artifacts(run_id, name, str(into)))
    except (MlflowException, OSError) as exc:
        raise LinkageError(f"run {run_id} has no artefact {name!r}") from exc


def load_source(client: MlflowClient, ref: LinkageRef) -> SourceLinkage:
    """Returns the linkage document a reference points at, with its run's tags.

    A cell's genome is turned into a document with `sim.linkage_doc.to_document` in the
    run's `mode` (param; default "paper").

    Raises:
        LinkageError: unknown run, missing artefact, or a cell not in the repertoire.
    """
    from mlflow.exceptions import MlflowException

    try:
        run = client.get_run(ref.run_id)
    except MlflowException as exc:
        raise LinkageError(f"--linkage: no MLflow run with id {ref.run_id!r}") from exc
    tags = run.data.tags
    with tempfile.TemporaryDirectory() as tmp:
        if ref.cell is None:
            path = _download(client, ref.run_id, "best_linkage.json", Path(tmp))
            document = json.loads(path.read_text(encoding="utf-8"))
        else:
            document = _cell_document(client, ref, run.data.params.get("mode", "paper"), Path(tmp))
    return SourceLinkage(
        run_id=ref.run_id,
        cell=ref.cell,
        experiment_id=run.info.experiment_id,
        approach=tags.get("approach", "unknown"),
        fitness=tags.get("fitness", "unknown"),
        document=document,
    )


def _cell_document(client: MlflowClient, ref: LinkageRef, mode: str, tmp: Path) -> dict:
    import pyarrow.parquet as pq

    from sim.linkage_doc import to_document

    table = pq.read_table(_download(client, ref.run_id, "repertoire.parquet", tmp))
    cells = table.column("cell").to_pylist()
    if ref.cell not in cells:
        raise LinkageError(
            f"--linkage {ref.run_id}:{ref.cell}: cell {ref.cell} is not in the repertoire "
            f"({len(cells)} filled cells)"
        )
    genome = np.asarray(table.column("genome")[cells.index(ref.cell)].as_py(), dtype=float)
    return to_document(genome, mode)
