"""Provides trial checkpoints: optimizer state plus bookkeeping in one atomic npz file."""

from __future__ import annotations

import csv
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from linkevo.sim.errors import LinkevoError
from linkevo.workers.store.artifacts import read_npz, write_npz_atomic

CHECKPOINT_FILE = "state.npz"
"""The checkpoint file inside a trial's `checkpoint/` folder."""


@dataclass(frozen=True)
class Checkpoint:
    """A saved trial.

    Attributes:
        state: the optimizer's `state_dict()`.
        rows: how many metrics.csv rows the trial had written when it was saved.
        spec: the trial spec as saved (JSON-able dict).
    """

    state: dict[str, np.ndarray]
    rows: int
    spec: dict[str, object]


def save_checkpoint(folder: Path, checkpoint: Checkpoint) -> Path:
    """Writes the checkpoint to `folder/state.npz` atomically; returns the file path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / CHECKPOINT_FILE
    arrays = dict(checkpoint.state)
    arrays["checkpoint.rows"] = np.array(checkpoint.rows, dtype=np.int64)
    arrays["checkpoint.spec"] = np.array(json.dumps(checkpoint.spec, sort_keys=True))
    write_npz_atomic(path, arrays)
    return path


class CheckpointError(LinkevoError, ValueError):
    """A trial's checkpoint (or the metrics.csv it continues) cannot be resumed from.

    Attributes:
        path: the damaged file.
        problem: what is wrong with it.
    """

    def __init__(self, path: Path, problem: str) -> None:
        super().__init__(
            f"cannot resume from {path}: {problem}; the trial must start afresh "
            "(`linkevo trial` without --resume, or `linkevo grid CONFIG --resume "
            "--restart-trial KEY`)"
        )
        self.path = path
        self.problem = problem


def load_checkpoint(folder: Path) -> Checkpoint | None:
    """Returns the checkpoint in `folder`, or None when there is none.

    Raises:
        CheckpointError: naming the file when it is truncated, not an npz, or lacks or
            holds impossible bookkeeping entries (the search state itself is checked as
            the optimizer loads it, `workers.trial`).
    """
    path = folder / CHECKPOINT_FILE
    if not path.is_file():
        return None
    try:
        arrays = read_npz(path)
        rows = int(arrays.pop("checkpoint.rows"))
        spec = json.loads(str(arrays.pop("checkpoint.spec")[()]))
    except (zipfile.BadZipFile, OSError, EOFError, KeyError, ValueError) as exc:
        raise CheckpointError(path, f"the file is damaged ({type(exc).__name__}: {exc})") from exc
    if rows < 0 or not isinstance(spec, dict):
        raise CheckpointError(path, f"its bookkeeping is impossible (rows {rows}, spec {spec!r})")
    return Checkpoint(state=arrays, rows=rows, spec=spec)


def checkpointed_rows(metrics: Path, rows: int) -> list[dict[str, float]]:
    """Returns the first `rows` rows of a trial's metrics.csv, the ones its checkpoint
    counts; rows after them (a partial row a killed writer left, say) are not read.

    Raises:
        CheckpointError: naming the file when it holds fewer whole rows than that.
    """
    kept: list[dict[str, float]] = []
    if rows == 0:
        return kept
    try:
        with open(metrics, newline="") as handle:
            reader = csv.reader(handle)
            header = next(reader, None)
            for line, values in enumerate(reader, start=2):
                if len(kept) == rows:
                    break
                if header is None or len(values) != len(header):
                    raise CheckpointError(metrics, f"row {line} has {len(values)} fields")
                try:
                    kept.append({k: float(v) for k, v in zip(header, values, strict=True)})
                except ValueError as exc:
                    raise CheckpointError(metrics, f"row {line} is not numbers ({exc})") from exc
    except FileNotFoundError:
        pass
    if len(kept) < rows:
        raise CheckpointError(
            metrics, f"it holds {len(kept)} whole rows but the checkpoint counts {rows}"
        )
    return kept
