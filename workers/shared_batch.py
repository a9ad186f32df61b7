"""Provides SharedBatch: a genome batch and its Evaluation in one shared-memory file.

An `ActorPoolEvaluator` and evaluator actors on the same Ray node exchange each batch
through such a file instead of the object store: the caller writes the genomes in, every
actor maps the same file and evaluates its rows straight into the Evaluation arrays there,
and the caller hands those arrays on without copying them. Ray carries only a few bytes per
call (docs/grid.md, "Evaluator transport").
"""

from __future__ import annotations

import mmap
import os
import uuid
import weakref
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from linkevo.sim.evaluation import ALIGNMENT, Evaluation
from linkevo.sim.genome import N_GENES
from linkevo.workers.result_pool import Root

SHARED_DIR = Path("/dev/shm")
"""Where batch files live: a memory-backed file system (Linux)."""
PREFIX = "linkevo-batch-"


@dataclass(frozen=True)
class SharedLayout:
    """What an actor needs to map a SharedBatch: the file, its Ray node and its shape.

    Attributes:
        path: the batch file.
        node_id: the Ray node whose file system holds it.
        capacity: genome rows it holds.
        n_angles: crank angles of its Evaluation.
        n_objectives: losses per genome (1 or 2).
    """

    path: str
    node_id: str
    capacity: int
    n_angles: int
    n_objectives: int

    @property
    def genome_bytes(self) -> int:
        """Bytes of the genome block (capacity, 56) at the start of the file."""
        return -(-self.capacity * N_GENES * 8 // ALIGNMENT) * ALIGNMENT

    @property
    def nbytes(self) -> int:
        """The file's size: the genome block, then the Evaluation arrays."""
        return self.genome_bytes + Evaluation.nbytes_for(
            self.capacity, self.n_angles, self.n_objectives
        )

    def as_tuple(self) -> tuple:
        """Returns the fields as a plain tuple (cheaper to send than the dataclass)."""
        return (self.path, self.node_id, self.capacity, self.n_angles, self.n_objectives)


class SharedBatch:
    """A genome batch and its Evaluation laid out in one memory-mapped file.

    A `workers.result_pool.ResultBuffer`: arrays handed out by `evaluation()` stay valid
    after `release()` deletes the file, for as long as they are referenced.

    Attributes:
        layout: how to find and map it.
        capacity: genome rows it holds.
        genomes: (capacity, 56) float64 view of the genome block.
    """

    def __init__(self, layout: SharedLayout, mapping: mmap.mmap):
        self.layout = layout
        self.capacity = layout.capacity
        self.genomes = np.ndarray((layout.capacity, N_GENES), np.float64, mapping, 0)
        # Every array `evaluation()` hands out is a view whose base is this one array, so
        # its reference count tells whether any of them is still alive (`busy`).
        self._results = Root(
            lambda: np.frombuffer(
                mapping,
                np.uint8,
                count=layout.nbytes - layout.genome_bytes,
                offset=layout.genome_bytes,
            )
        )

    @classmethod
    def create(cls, node_id: str, capacity: int, n_angles: int, n_objectives: int) -> SharedBatch:
        """Returns a new batch file in SHARED_DIR; the file is deleted by `release` or when
        the object is freed.

        Raises:
            OSError: when the file cannot be made or its memory reserved (e.g. ENOSPC).
        """
        remove_orphans()
        path = SHARED_DIR / f"{PREFIX}{os.getpid()}-{uuid.uuid4().hex[:12]}"
        layout = SharedLayout(str(path), node_id, capacity, n_angles, n_objectives)
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o600)
        try:
            # Reserve the pages now: a full tmpfs (Docker gives /dev/shm 64 MB) then fails
            # here with ENOSPC instead of killing the process with SIGBUS on first write.
            os.posix_fallocate(fd, 0, layout.nbytes)
            mapping = mmap.mmap(fd, layout.nbytes)
        except OSError:
            path.unlink(missing_ok=True)
            raise
        finally:
            os.close(fd)
        batch = cls(layout, mapping)
        batch._finalizer = weakref.finalize(batch, _unlink, str(path))
        return batch

    @classmethod
    def attach(cls, layout: SharedLayout) -> SharedBatch:
        """Returns a view of an existing batch file (raises OSError if it cannot be
        mapped)."""
        fd = os.open(layout.path, os.O_RDWR)
        try:
            mapping = mmap.mmap(fd, layout.nbytes)
        finally:
            os.close(fd)
        return cls(layout, mapping)

    def evaluation(self) -> Evaluation:
        """Returns the file's Evaluation (capacity rows), as views into the mapping."""
        layout = self.layout
        return Evaluation.empty(
            layout.capacity, layout.n_angles, layout.n_objectives, buffer=self._results.array
        )

    @property
    def busy(self) -> bool:
        """Whether an array from `evaluation()` (or a view of one) is still alive."""
        return self._results.busy

    def release(self) -> None:
        """Deletes the batch file now (mappings stay valid until freed; idempotent)."""
        finalizer = getattr(self, "_finalizer", None)
        if finalizer is not None:
            finalizer()


def _unlink(path: str) -> None:
    Path(path).unlink(missing_ok=True)


def remove_orphans() -> list[Path]:
    """Deletes the batch files of processes that no longer run; returns them.

    A trial process killed outright (a lost node, SIGKILL) cannot delete its files; the
    next batch file made on the machine clears them. The owner is the pid in the name.
    """
    removed = []
    for path in SHARED_DIR.glob(f"{PREFIX}*"):
        pid = path.name[len(PREFIX) :].split("-", 1)[0]
        if pid.isdigit() and not _running(int(pid)):
            path.unlink(missing_ok=True)
            removed.append(path)
    return removed


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    return True


def shared_memory_available() -> bool:
    """Returns whether batch files can be created here (a writable SHARED_DIR)."""
    return SHARED_DIR.is_dir() and os.access(SHARED_DIR, os.W_OK | os.X_OK)
