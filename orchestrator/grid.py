"""Provides Grid: a config expanded into trial cells with deterministic seeds and keys."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import zlib
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import numpy as np

from linkevo.orchestrator.config import GridConfig
from linkevo.workers.store.run_layout import trial_key

_REPO_ROOT = Path(__file__).resolve().parent.parent
CODE_VERSION_ENV = "LINKEVO_CODE_VERSION"
"""Environment variable that overrides the detected code version."""


@dataclass(frozen=True)
class TrialCell:
    """One trial of the grid.

    Attributes:
        approach: search approach, e.g. "MAP-LIS".
        fitness: fitness function, e.g. "Fp".
        index: trial number within its (approach, fitness) cell, 0-based.
        seed: the trial's seed, derived from the grid seed and the cell.
    """

    approach: str
    fitness: str
    index: int
    seed: int

    @property
    def key(self) -> str:
        """The trial key, e.g. "MAP-LIS/Fp/03"; unique within a grid and stable across runs."""
        return trial_key(self.approach, self.fitness, self.index)

    @property
    def dirname(self) -> str:
        """The trial key as a single folder name, e.g. "MAP-LIS_Fp_03"."""
        return self.key.replace("/", "_")


def trial_seed(grid_seed: int, approach: str, fitness: str, index: int) -> int:
    """Returns the seed of one trial, in [0, 2**32).

    The seed depends only on the grid seed and the cell's names and index (not on which
    other approaches or how many trials the grid holds), via a SeedSequence spawn key.
    """
    spawn_key = (zlib.crc32(approach.encode()), zlib.crc32(fitness.encode()), index)
    sequence = np.random.SeedSequence(grid_seed, spawn_key=spawn_key)
    return int(sequence.generate_state(1, dtype=np.uint32)[0])


def code_version() -> str:
    """Returns the code version: LINKEVO_CODE_VERSION when set (e.g. an image tag), else the
    git commit (with "-dirty" for local edits), else the installed package version."""
    if os.environ.get(CODE_VERSION_ENV):
        return os.environ[CODE_VERSION_ENV]
    try:
        out = subprocess.run(
            ["git", "-C", str(_REPO_ROOT), "describe", "--always", "--dirty", "--abbrev=12"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        )
        return out.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return metadata.version("linkevo")


@dataclass(frozen=True)
class Grid:
    """A config expanded into its trials.

    Attributes:
        config: the resolved config.
        code_version: the code version the grid id includes.
        cells: the trials, approach-major then fitness then index.
    """

    config: GridConfig
    code_version: str
    cells: tuple[TrialCell, ...]

    @classmethod
    def from_config(cls, config: GridConfig, version: str | None = None) -> Grid:
        """Returns the grid of `config` at `version` (default: the current code version)."""
        cells = tuple(
            TrialCell(a, f, i, trial_seed(config.seed, a, f, i))
            for a in config.approaches
            for f in config.fitnesses
            for i in range(config.trials)
        )
        return cls(config=config, code_version=version or code_version(), cells=cells)

    @property
    def grid_id(self) -> str:
        """A 12-hex-digit hash of the result-determining config keys and the code version."""
        payload = json.dumps(
            {"config": self.config.identity(), "code_version": self.code_version},
            sort_keys=True,
        )
        return hashlib.sha256(payload.encode()).hexdigest()[:12]

    def cell(self, key: str) -> TrialCell:
        """Returns the cell with trial key `key`."""
        for cell in self.cells:
            if cell.key == key:
                return cell
        raise KeyError(key)


def work_root(config: GridConfig, tracking_uri: str) -> Path:
    """Returns the folder holding `trials/<grid_id>/...`: `work_dir`, else the embedded
    store's folder, else `./runs`."""
    if config.work_dir:
        return Path(config.work_dir).expanduser().resolve()
    if tracking_uri.startswith("sqlite:///"):
        return Path(tracking_uri.removeprefix("sqlite:///")).parent
    return Path("runs").resolve()


def grid_record(root: Path, grid: Grid) -> Path:
    """Returns the file beside a grid's trial folders that says which store and parent run
    the grid's trials belong to (`grid.json`, written by the driver)."""
    return root / "trials" / grid.grid_id / "grid.json"


def trial_dir(root: Path, grid: Grid, cell: TrialCell) -> Path:
    """Returns a trial's folder for its files and checkpoints."""
    return root / "trials" / grid.grid_id / cell.dirname
