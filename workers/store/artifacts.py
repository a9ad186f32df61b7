"""Provides atomic writers for trial artefacts (JSON, npz, parquet, text, any file)."""

from __future__ import annotations

import errno
import json
import os
import secrets
import shutil
import socket
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from linkevo.sim.errors import LinkevoError

TEMP_INFIX = ".tmp-"
"""Marks a temporary file: `.<stem>.tmp-<host>-<pid>-<random><suffix>` beside its target."""


def _temp_name(path: Path) -> Path:
    token = secrets.token_hex(4)
    return path.with_name(
        f".{path.stem}{TEMP_INFIX}{socket.gethostname()}-{os.getpid()}-{token}{path.suffix}"
    )


def process_alive(pid: int) -> bool:
    """Whether a process with this pid runs on this host (as any user)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


WRITER_LOCK = ".linkevo-writer.lock"
"""The file of a folder's writer lock (`writer_lock`)."""


class FolderBusy(LinkevoError):
    """Another process writes the folder; the message names it."""


@contextmanager
def writer_lock(folder: Path, what: str) -> Iterator[None]:
    """Holds the folder's writer lock while the block runs: one process at a time writes a
    trial's folder. The lock is the kernel's (`fcntl.flock` on `WRITER_LOCK`), so a writer
    that dies frees it at once; the file names the holder for the refusal.

    Raises:
        FolderBusy: another process holds it (named, with what to do).
    """
    import fcntl
    import time

    folder.mkdir(parents=True, exist_ok=True)
    path = folder / WRITER_LOCK
    with open(path, "a+", encoding="utf-8") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.seek(0)
            holder = handle.read().strip() or "another process"
            raise FolderBusy(
                f"{str(folder)!r} is being written by {holder} ({what}); wait for it to end or "
                "stop it, then --resume"
            ) from None
        handle.seek(0)
        handle.truncate()
        since = time.strftime("%Y-%m-%d %H:%M:%S")
        handle.write(f"pid {os.getpid()} on {socket.gethostname()} since {since}\n")
        handle.flush()
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def sweep_stale_temps(path: Path) -> list[Path]:
    """Deletes the temporary files that writers of `path` on this host left when they
    died (their pid no longer runs); returns them. Live writers' and other hosts' files
    (a shared folder) are left alone."""
    prefix = f".{path.stem}{TEMP_INFIX}{socket.gethostname()}-"
    swept = []
    for candidate in path.parent.glob(f"{prefix}*{path.suffix}"):
        pid = candidate.name.removeprefix(prefix).partition("-")[0]
        if pid.isdigit() and not process_alive(int(pid)):
            candidate.unlink(missing_ok=True)
            swept.append(candidate)
    return swept


def _fsync(path: Path, directory: bool = False) -> None:
    fd = os.open(path, os.O_RDONLY | (os.O_DIRECTORY if directory else 0))
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextmanager
def atomic_path(path: Path, need: int | None = None) -> Iterator[Path]:
    """Yields a temporary path beside `path`; on success it replaces `path` atomically.

    The one way linkevo writes a file: the temporary file lives in the same folder (so
    `os.replace` is atomic), keeps the suffix (writers that pick a format by suffix still
    work) and is created with mode 0666 less the umask, so the result is as readable as
    any file the user makes. Before the rename the file is fsynced, and the folder after
    it. Stale temporary files of dead writers of the same path are swept first. On error
    the temporary file is removed and `path` is left as it was; a block that deletes the
    temporary file itself leaves `path` as it was too. A full disk (or quota) is an
    OSError naming the file, the bytes it needs (`need`, when the caller knows them) or had
    written, and the space free there.
    """
    path = Path(path)
    sweep_stale_temps(path)
    tmp = _temp_name(path)
    written = 0
    try:
        os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        try:
            yield tmp
            if not tmp.exists():
                return
            _fsync(tmp)
            os.replace(tmp, path)
            _fsync(path.parent, directory=True)
        except BaseException:
            written = tmp.stat().st_size if tmp.exists() else 0
            tmp.unlink(missing_ok=True)
            raise
    except OSError as exc:
        if exc.errno in (errno.ENOSPC, errno.EDQUOT):
            raise disk_full(path, need, written) from exc
        raise


def disk_full(path: Path, need: int | None, written: int) -> OSError:
    """Returns the error of a write to `path` that found its disk (or quota) full: the
    file, the bytes it needs (or had written) and the space free there."""
    free = shutil.disk_usage(path.parent).free
    size = f"it needs {need:,} bytes" if need is not None else f"it had {written:,} bytes"
    return OSError(
        errno.ENOSPC,
        f"no space left writing {path} ({size}; {free:,} bytes are free on that "
        "filesystem); free space there, or point work_dir (or --out) at a larger disk",
        str(path),
    )


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Writes `data` to `path` atomically (see `atomic_path`)."""
    with atomic_path(path, need=len(data)) as tmp:
        tmp.write_bytes(data)


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


def read_npz(path: Path) -> dict[str, np.ndarray]:
    """Returns every array of an `.npz` file, loaded without pickle, each array's header
    checked against the bytes it holds before memory is taken for it.

    Raises:
        ValueError: naming an array whose header claims more data than the file holds
            (a damaged or forged file: a shape of (10**12, 56), say).
    """
    import zipfile

    with zipfile.ZipFile(path) as archive:
        for info in archive.infolist():
            with archive.open(info) as member:
                version = np.lib.format.read_magic(member)
                read_header = (
                    np.lib.format.read_array_header_1_0
                    if version == (1, 0)
                    else np.lib.format.read_array_header_2_0
                )
                shape, _, dtype = read_header(member)
                claimed = int(np.prod(shape, dtype=object)) * dtype.itemsize
                held = info.file_size - member.tell()
                if claimed > held:
                    raise ValueError(
                        f"array {info.filename.removesuffix('.npy')!r} claims shape {shape} "
                        f"({claimed:,} bytes) but holds {held:,} bytes"
                    )
    with np.load(path, allow_pickle=False) as data:
        return {name: data[name] for name in data.files}


def columns_to_table(columns: dict[str, np.ndarray], float32: tuple[str, ...] = ()) -> pa.Table:
    """Returns an Arrow table: 1-D arrays become columns, (N, k) arrays list<float64>
    (list<float32> for the columns named in `float32`)."""
    arrays = {}
    for name, value in columns.items():
        value = np.asarray(value)
        if value.ndim == 1:
            arrays[name] = pa.array(value)
        elif value.ndim == 2:
            n, k = value.shape
            offsets = pa.array(np.arange(n + 1, dtype=np.int32) * k)
            dtype = np.float32 if name in float32 else np.float64
            flat = pa.array(np.ascontiguousarray(value, dtype=dtype).reshape(-1))
            arrays[name] = pa.ListArray.from_arrays(offsets, flat)
        else:
            raise ValueError(f"column {name!r} must be 1-D or 2-D, got shape {value.shape}")
    return pa.table(arrays)


def write_parquet_atomic(
    path: Path, columns: dict[str, np.ndarray], float32: tuple[str, ...] = ()
) -> None:
    """Writes named columns (1-D, or (N, k) as list<float64>, list<float32> for the
    columns in `float32`) to zstd-compressed parquet atomically."""
    table = columns_to_table(columns, float32)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def read_document(path: Path) -> dict:
    """Returns the linkage document in a JSON file, its size checked before it is read and
    its nesting before it is parsed (`sim.linkage.linkage_doc.parse_document`).

    Raises:
        DocumentError: naming the file: missing, unreadable, too large or not a document.
    """
    from linkevo.sim.linkage.linkage_doc import (
        MAX_DOCUMENT_BYTES,
        DocumentError,
        check_document_size,
        parse_document,
    )

    path = Path(path)
    try:
        check_document_size(path.stat().st_size, str(path))
        with open(path, "rb") as handle:
            data = handle.read(MAX_DOCUMENT_BYTES + 1)
    except OSError as exc:
        raise DocumentError(f"{path}: cannot read the linkage document ({exc.strerror})") from exc
    return parse_document(data, str(path))
