"""Provides the tables a trial leaves in its run and linkevo reads back: the repertoire (or
population) and the walk map. Here are their columns, which descriptor space their bins
belong to and how 4-D bins fold onto a 2-D map, and their checks by content: a table read
back from a store (`read_repertoire`, `read_walk_map`) is refused with an `ArtefactError`
naming the file, its run and the remedy unless it holds what its writer writes.

A repertoire has a row per filled cell: cell (int64, -1 outside an archive), loss, error,
angle_error, desc_0..desc_{D-1}, bin_0..bin_{D-1} (archives), genome (56 genes), sigma,
foot_x and foot_y (A crank angles, NaN at failed ones), plus an approach's extras
(`algorithms.optimizer.BaseOptimizer.view`). A walk map has a row per cell and floor:
`sim.robot.walk_rows.COLUMNS` and the cell's bins.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.sim.errors import LinkevoError
from linkevo.sim.linkage.descriptors import DESCRIPTOR_SPACES, DescriptorSpace
from linkevo.sim.linkage.genome import N_GENES
from linkevo.sim.robot.walk_rows import COLUMNS as WALK_MAP_COLUMNS
from linkevo.sim.robot.walk_rows import FLOOR_ORDER, LATER_COLUMNS, STATUSES, Status

REPERTOIRE_COLUMNS: tuple[str, ...] = ("cell", "loss", "genome")
"""The columns every reader of a repertoire or population needs (with its bins)."""


class ArtefactError(LinkevoError, ValueError):
    """An artefact read back from a run that does not hold what its writer writes."""

    def __init__(self, name: str, run_id: str, problem: str, remedy: str) -> None:
        super().__init__(f"{name} of run {run_id} {problem}; {remedy}")


def bin_columns(columns: pd.Index | list[str]) -> list[str]:
    """Returns a table's bin columns bin_0, bin_1, ... in order."""
    found = [c for c in columns if c.startswith("bin_")]
    return sorted(found, key=lambda c: int(c.removeprefix("bin_")))


def space_of(approach: str, dims: int) -> DescriptorSpace:
    """Returns the approach's descriptor space (a generic one for an unknown approach)."""
    space = DESCRIPTOR_SPACES.get(approach)
    if space is not None and space.dims == dims:
        return space
    side = round(10_000 ** (1 / dims))
    return DescriptorSpace(tuple(f"d{i}" for i in range(dims)), side, (1.0,) * dims)


def fold_bins(bins: np.ndarray, resolution: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Returns (rows (N,), cols (N,), side) placing D-dimensional bins on a 2-D image.

    The second descriptor runs along x (columns), the first up y (rows), as in the
    explorer's default arrangement: 2-D bins (b0, b1) map to row b0, column b1. 4-D bins
    (b0, b1, b2, b3) fold to row = b0 * R + b2, column = b1 * R + b3: b0 and b1 choose an
    R × R block (outer axes), b2 and b3 the cell inside it (inner axes), so R = 10 gives a
    100 × 100 image.

    Args:
        bins: (N, D) int bins, D in {2, 4}.
        resolution: R, bins per dimension.
    """
    bins = np.asarray(bins, dtype=np.int64)
    if bins.shape[1] == 2:
        return bins[:, 0], bins[:, 1], resolution
    if bins.shape[1] == 4:
        rows = bins[:, 0] * resolution + bins[:, 2]
        cols = bins[:, 1] * resolution + bins[:, 3]
        return rows, cols, resolution * resolution
    raise ValueError(f"can fold 2-D or 4-D bins only, got {bins.shape[1]}-D")


def axis_names(space: DescriptorSpace) -> tuple[str, str]:
    """Returns the (x, y) axis names of a folded map as `fold_bins` places the bins: the
    second descriptor along x, the first up y; on a 4-D map outer › inner on each axis."""
    names = space.names
    if space.dims == 2:
        return names[1], names[0]
    return f"{names[1]} › {names[3]}", f"{names[0]} › {names[2]}"


def _read(path: Path, name: str, run_id: str, remedy: str) -> pd.DataFrame:
    import pyarrow as pa

    try:
        return pd.read_parquet(path)
    except (OSError, ValueError, pa.ArrowException) as exc:
        raise ArtefactError(
            name, run_id, f"is not a readable parquet table ({type(exc).__name__}: {exc})", remedy
        ) from exc


def read_repertoire(path: Path, run_id: str, name: str) -> pd.DataFrame:
    """Returns a run's repertoire or population table read from `path`, checked by content.

    Args:
        name: the artefact's name (`repertoire.parquet` or `population.parquet`).

    Raises:
        ArtefactError: unreadable, no rows, a column missing, genomes that are not 56
            genes in [0, 1), cells that are negative (in a repertoire) or repeated,
            non-finite losses, or bins that do not match the descriptors.
    """
    remedy = (
        "it was damaged or replaced after the trial wrote it: restore the run's artefacts "
        "from a backup, or run the trial again"
    )
    table = _read(path, name, run_id, remedy)

    def fail(problem: str) -> ArtefactError:
        return ArtefactError(name, run_id, problem, remedy)

    missing = [c for c in REPERTOIRE_COLUMNS if c not in table.columns]
    if missing:
        raise fail(f"lacks the column(s) {', '.join(missing)}")
    if table.empty:
        raise fail("holds no rows")
    try:
        genomes = np.stack(table["genome"].to_numpy()).astype(np.float64)
    except (TypeError, ValueError) as exc:
        raise fail(f"has genomes that are not rows of numbers ({exc})") from exc
    if genomes.shape[1:] != (N_GENES,) or not ((genomes >= 0) & (genomes < 1)).all():
        raise fail(f"has genomes that are not {N_GENES} genes in [0, 1)")
    cells, loss = table["cell"].to_numpy(), table["loss"].to_numpy()
    if cells.dtype.kind != "i" or loss.dtype.kind != "f" or not np.isfinite(loss).all():
        raise fail("has cells that are not integers or losses that are not finite numbers")
    bins = bin_columns(table.columns)
    if bins:
        if (cells < 0).any() or not table["cell"].is_unique:
            raise fail("has negative or repeated cells")
        values = table[bins].to_numpy()
        if values.dtype.kind != "i" or (values < 0).any():
            raise fail("has bins that are not non-negative integers")
    return table


def _check_cell_floor_rows(frame: pd.DataFrame, columns, fail) -> None:
    """Raises `fail(problem)` unless a table of a row per cell and floor has `columns`,
    integer cells, known floors and no (cell, floor) pair twice."""
    missing = [c for c in columns if c not in frame.columns]
    if missing:
        raise fail(f"lacks the column(s) {', '.join(missing)}")
    if frame["cell"].to_numpy().dtype.kind != "i":
        raise fail("has cells that are not integers")
    unknown = sorted(set(frame["floor"]) - set(FLOOR_ORDER))
    if unknown:
        raise fail(f"has unknown floors: {', '.join(map(repr, unknown))}")
    if frame.duplicated(["cell", "floor"]).any():
        raise fail("holds a cell and floor twice")


def read_walk_map(path: Path, run_id: str) -> pd.DataFrame:
    """Returns a run's walk map read from `path`, checked by content, with `breaks` as
    bool.

    Raises:
        ArtefactError: unreadable, a column missing, an unknown floor or status, a
            (cell, floor) pair twice, or a sound walk (walked, not breaking) without a
            finite distance.
    """
    from linkevo.workers.store.run_layout import WALK_MAP

    remedy = (
        "it was damaged or replaced after linkevo walkmap wrote it: walk the map anew with "
        f"linkevo walkmap {run_id} --restart"
    )
    frame = _read(path, WALK_MAP, run_id, remedy)

    def fail(problem: str) -> ArtefactError:
        return ArtefactError(WALK_MAP, run_id, problem, remedy)

    frame = frame.reindex(columns=[*frame.columns, *(set(LATER_COLUMNS) - set(frame.columns))])
    _check_cell_floor_rows(frame, WALK_MAP_COLUMNS, fail)
    unknown = sorted(set(frame["status"]) - STATUSES)
    if unknown:
        raise fail(f"has unknown statuses: {', '.join(map(repr, unknown))}")
    breaks = frame["breaks"]
    if not breaks.map(lambda v: isinstance(v, bool | np.bool_)).all():
        raise fail("has a breaks column that is not true or false")
    frame = frame.assign(breaks=breaks.astype(bool))
    distance = pd.to_numeric(frame["mean_distance_cm"], errors="coerce").to_numpy(dtype=float)
    sound = (frame["status"] == Status.WALKED).to_numpy() & ~frame["breaks"].to_numpy()
    if not np.isfinite(distance[sound]).all():
        raise fail("has walks that do not break but have no finite distance")
    return frame.assign(mean_distance_cm=distance)


PREDICTION_COLUMNS = ("cell", "floor", "predicted_cm", "spread_cm", "p_break")
"""A `walkpred.parquet` row per cell and floor (then the cell's bins): the distance the
walk model predicts in 10 s (cm), its spread (the ensemble's standard deviation, cm) and
the probability that the robot breaks."""


def read_walk_prediction(path: Path, run_id: str) -> pd.DataFrame:
    """Returns a run's predicted walks (`linkevo walkmodel predict`) read from `path`,
    checked by content.

    Raises:
        ArtefactError: unreadable, a column missing, an unknown floor, a (cell, floor)
            pair twice, or figures that are not numbers.
    """
    from linkevo.workers.store.run_layout import WALK_PREDICTION

    remedy = f"predict it anew with: linkevo walkmodel predict {run_id}"
    frame = _read(path, WALK_PREDICTION, run_id, remedy)

    def fail(problem: str) -> ArtefactError:
        return ArtefactError(WALK_PREDICTION, run_id, problem, remedy)

    _check_cell_floor_rows(frame, PREDICTION_COLUMNS, fail)
    figures = frame[["predicted_cm", "spread_cm", "p_break"]]
    if any(figures[c].to_numpy().dtype.kind != "f" for c in figures):
        raise fail("has figures that are not numbers")
    return frame


def read_prediction_map(path: Path, run_id: str) -> pd.DataFrame:
    """Returns a SAIL trial's prediction map (`workers.walk_sail`) read from `path`, checked
    by content as a repertoire is, with its predicted walks per floor.

    Raises:
        ArtefactError: as `read_repertoire`, or a floor's predictions missing or not
            numbers.
    """
    from linkevo.workers.store.run_layout import PREDICTION_MAP

    table = read_repertoire(path, run_id, PREDICTION_MAP)
    wanted = [f"{floor}_{figure}" for floor in FLOOR_ORDER for figure in PREDICTION_COLUMNS[2:]]
    bad = [c for c in wanted if c not in table or table[c].to_numpy().dtype.kind != "f"]
    if bad:
        raise ArtefactError(
            PREDICTION_MAP,
            run_id,
            f"lacks the predictions {', '.join(bad)} (or they are not numbers)",
            "it was damaged or replaced after the trial wrote it: run the trial again",
        )
    return table


def prediction_rows(table: pd.DataFrame) -> pd.DataFrame:
    """Returns a prediction map's predicted walks as `walkpred.parquet` holds them: a row
    per cell and floor (`PREDICTION_COLUMNS`, then the cell's bins)."""
    bins = bin_columns(table.columns)
    parts = [
        pd.DataFrame(
            {
                "cell": table["cell"].to_numpy(),
                "floor": floor,
                **{f: table[f"{floor}_{f}"].to_numpy() for f in PREDICTION_COLUMNS[2:]},
                **{b: table[b].to_numpy() for b in bins},
            }
        )
        for floor in FLOOR_ORDER
    ]
    return pd.concat(parts, ignore_index=True)
