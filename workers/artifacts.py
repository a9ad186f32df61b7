"""Provides atomic writers for trial artefacts (JSON, npz, parquet, text, any file)."""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """Yields a temporary path beside `path`; on success it replaces `path` atomically.

    The temporary file lives in the same directory (so `os.replace` is atomic) and keeps
    the suffix (so writers that choose a format by suffix still work). On error it is
    removed and `path` is left as it was.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Writes `data` to `path` atomically (flushed and fsynced before the rename)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())


def write_text_atomic(path: Path, text: str) -> None:
    """Writes UTF-8 `text` to `path` atomically."""
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: Path, doc: object) -> None:
    """Writes `doc` as indented JSON to `path` atomically."""
    write_text_atomic(path, json.dumps(doc, indent=2, sort_keys=False) + "\n")


def write_npz_atomic(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Writes numpy arrays to an uncompressed `.npz` at `path` atomically (no pickles).

    Raises:
        ValueError: when an array has dtype object (it would need pickle).
    """
    for name, value in arrays.items():
        if np.asarray(value).dtype == object:
            raise ValueError(f"array {name!r} has dtype object; npz artefacts never pickle")
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **arrays)
        f.flush()
        os.fsync(f.fileno())


def read_npz(path: Path) -> dict[str, np.ndarray]:
    """Returns every array of an `.npz` file, loaded without pickle."""
    with np.load(path, allow_pickle=False) as data:
        return {name: data[name] for name in data.files}


def columns_to_table(columns: dict[str, np.ndarray]) -> pa.Table:
    """Returns an Arrow table: 1-D arrays become columns, (N, k) arrays list<float64>."""
    arrays = {}
    for name, value in columns.items():
        value = np.asarray(value)
        if value.ndim == 1:
            arrays[name] = pa.array(value)
        elif value.ndim == 2:
            n, k = value.shape
            offsets = pa.array(np.arange(n + 1, dtype=np.int32) * k)
            flat = pa.array(np.ascontiguousarray(value, dtype=np.float64).reshape(-1))
            arrays[name] = pa.ListArray.from_arrays(offsets, flat)
        else:
            raise ValueError(f"column {name!r} must be 1-D or 2-D, got shape {value.shape}")
    return pa.table(arrays)


def write_parquet_atomic(path: Path, columns: dict[str, np.ndarray]) -> None:
    """Writes named columns (1-D, or (N, k) as list<float64>) to parquet atomically."""
    table = columns_to_table(columns)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)
