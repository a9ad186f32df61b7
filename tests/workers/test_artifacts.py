"""The one atomic writer: modes as the umask says, durable renames, no leftovers."""

from __future__ import annotations

import errno
import os
import signal
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from linkevo.workers.store.artifacts import (
    TEMP_INFIX,
    atomic_path,
    read_npz,
    write_bytes_atomic,
    write_npz_atomic,
    write_parquet_atomic,
)

KILLED_WRITER = """
import os, signal, sys
from pathlib import Path
from linkevo.workers.store.artifacts import atomic_path
with atomic_path(Path(sys.argv[1])) as tmp:
    tmp.write_bytes(b"half a checkpoint")
    os.kill(os.getpid(), signal.SIGKILL)
"""


@pytest.mark.parametrize(("umask", "mode"), [(0o022, 0o644), (0o002, 0o664), (0o077, 0o600)])
def test_files_are_as_readable_as_the_umask_allows(tmp_path: Path, umask: int, mode: int):
    previous = os.umask(umask)
    try:
        write_bytes_atomic(tmp_path / "a.json", b"{}")
        write_npz_atomic(tmp_path / "state.npz", {"x": np.arange(3)})
        write_parquet_atomic(tmp_path / "r.parquet", {"loss": np.zeros(2)})
        with atomic_path(tmp_path / "p.png") as tmp:
            tmp.write_bytes(b"png")
    finally:
        os.umask(previous)
    for name in ("a.json", "state.npz", "r.parquet", "p.png"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == mode, name


def test_a_killed_writers_temp_file_is_swept_by_the_next_write(tmp_path: Path):
    target = tmp_path / "state.npz"
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run([sys.executable, "-c", KILLED_WRITER, str(target)], cwd=root)
    assert proc.returncode == -signal.SIGKILL
    (left,) = tmp_path.glob(f".state{TEMP_INFIX}*.npz")
    assert left.read_bytes() == b"half a checkpoint" and not target.exists()
    write_npz_atomic(target, {"x": np.arange(4)})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.npz"]
    assert read_npz(target)["x"].tolist() == [0, 1, 2, 3]


def test_a_live_writers_temp_file_is_left_alone(tmp_path: Path):
    target = tmp_path / "metrics.csv"
    with atomic_path(target) as mine:
        mine.write_text("in progress")
        write_bytes_atomic(target, b"other writer")
        assert mine.exists()
    assert target.read_text() == "in progress"


def test_a_failed_write_leaves_the_old_file_and_no_temp(tmp_path: Path):
    target = tmp_path / "best_linkage.json"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_text("new")
        raise RuntimeError("writer failed")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["best_linkage.json"]


def test_parquet_is_zstd_and_keeps_float32_only_where_asked(tmp_path: Path):
    path = tmp_path / "repertoire.parquet"
    paths = np.random.default_rng(0).random((5, 40))
    genomes = np.random.default_rng(1).random((5, 56))
    write_parquet_atomic(path, {"foot_x": paths, "genome": genomes}, float32=("foot_x",))
    meta = pq.ParquetFile(path).metadata
    assert meta.row_group(0).column(0).compression == "ZSTD"
    table = pq.read_table(path)
    assert table.schema.field("foot_x").type.value_type == pa.float32()
    assert table.schema.field("genome").type.value_type == pa.float64()
    np.testing.assert_array_equal(np.stack(table.column("genome").to_numpy(False)), genomes)


def test_a_full_disk_names_the_file_and_the_space_it_needs(tmp_path, monkeypatch):
    """A full disk cannot be made here without root: the file system's answer is stood in
    for by the OS error a full disk raises when the data is written."""
    target = tmp_path / "best_linkage.json"
    target.write_bytes(b"the previous version")

    def full(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Path, "write_bytes", full)
    with pytest.raises(OSError) as caught:
        write_bytes_atomic(target, b"x" * 5000)
    monkeypatch.undo()
    message = str(caught.value)
    assert caught.value.errno == errno.ENOSPC
    assert f"no space left writing {target} (it needs 5,000 bytes;" in message
    assert "bytes are free on that filesystem" in message
    assert target.read_bytes() == b"the previous version"
    assert [p.name for p in tmp_path.iterdir()] == ["best_linkage.json"]  # no temp left
