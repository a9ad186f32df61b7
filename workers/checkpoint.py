"""Provides trial checkpoints: optimizer state plus bookkeeping in one atomic npz file."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workers.artifacts import read_npz, write_npz_atomic

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


def load_checkpoint(folder: Path) -> Checkpoint | None:
    """Returns the checkpoint in `folder`, or None when there is none."""
    path = folder / CHECKPOINT_FILE
    if not path.is_file():
        return None
    arrays = read_npz(path)
    rows = int(arrays.pop("checkpoint.rows"))
    spec = json.loads(str(arrays.pop("checkpoint.spec")[()]))
    return Checkpoint(state=arrays, rows=rows, spec=spec)
