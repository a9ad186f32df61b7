"""Provides the repertoire drawings a trial and a report share: folded maps and path maps.

A trial logs its own picture (`draw_trial_maps`) to its MLflow run; the report
(`orchestrator.report.figures`) draws the grid's figures with the same functions.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib import colormaps
from matplotlib.collections import LineCollection
from matplotlib.colors import ListedColormap, Normalize
from matplotlib.figure import Figure

from linkevo.algorithms.pareto import non_dominated_ranks
from linkevo.sim.study import is_map_elites, is_pareto
from linkevo.workers.store.artifacts import atomic_path
from linkevo.workers.store.tables import axis_names, bin_columns, fold_bins, space_of

DOWNSAMPLED = 5
"""Side of the downsampled path maps (5 × 5 cells, as in the study)."""
STRIP_PATHS = 5
"""Paths shown for EA (best of the final population) and NSGA-II (along the front)."""
LOSS_CMAP = "viridis_r"
"""Low (good) losses bright yellow, high ones dark purple: the explorer's colours too."""
PATH_CMAP = ListedColormap(colormaps[LOSS_CMAP](np.linspace(0.15, 1.0, 256)), "paths")
"""The same scale for foot paths drawn as lines on white, less its palest yellow end (a
pale yellow line would vanish on the page, and the best paths are the ones to see)."""
LOSS_LABEL = "loss (brighter is lower, better)"
CLIP_QUANTILE = 0.95
"""Loss colour scales end at this quantile of the losses shown."""


def loss_norm(losses: np.ndarray) -> Normalize:
    """Returns a colour scale from the lowest loss to the 95th percentile of `losses` (n,).

    A few very poor linkages would otherwise take most of the scale; losses above the
    percentile share the top colour (the colour bar shows an arrow).
    """
    if losses.size == 0:
        return Normalize(0.0, 1.0)
    low, high = float(losses.min()), float(np.quantile(losses, CLIP_QUANTILE))
    return Normalize(low, high if high > low else low + 1.0)


def select_paths(archive: pd.DataFrame, approach: str) -> pd.DataFrame:
    """Returns the archive rows to draw, with their grid position.

    MAP-Elites: the best row in each cell of the repertoire downsampled to 5 × 5 (folded
    4-D maps are downsampled after folding). NSGA-II: 5 rows evenly spaced along the
    final Pareto front, ordered by the first objective. EA: the 5 lowest losses.

    Returns:
        The chosen rows plus columns row, col (grid position, row 0 at the bottom).
    """
    valid = archive[archive.foot_x.map(lambda v: np.isfinite(np.asarray(v)).any())]
    if is_map_elites(approach):
        bins = bin_columns(valid.columns)
        space = space_of(approach, len(bins))
        valid = valid[valid.cell >= 0]
        rows, cols, side = fold_bins(valid[bins].to_numpy(), space.resolution)
        block = side // DOWNSAMPLED
        picked = valid.assign(row=rows // block, col=cols // block)
        best = picked.sort_values("loss").drop_duplicates(["row", "col"])
        return best.reset_index(drop=True)
    if is_pareto(approach):
        losses = valid[["loss_0", "loss_1"]].to_numpy()
        front = valid[non_dominated_ranks(losses) == 0].sort_values(["loss_0", "loss_1"])
        front = front.drop_duplicates(["loss_0", "loss_1"])
        take = np.unique(np.linspace(0, len(front) - 1, min(STRIP_PATHS, len(front))).round())
        chosen = front.iloc[take.astype(int)]
    else:
        chosen = valid.nsmallest(STRIP_PATHS, "loss")
    return chosen.assign(row=0, col=np.arange(len(chosen))).reset_index(drop=True)


def draw_paths(
    ax, chosen: pd.DataFrame, shape: tuple[int, int], norm: Normalize, label_size: float = 5.0
):
    """Draws each chosen path scaled into its grid cell, with its size in the corner (at
    `label_size` pt); the crank angles where the linkage fails are left as gaps (a path is
    closed only where its last and first angles both assemble).

    Returns the paths' LineCollection (coloured by loss under `norm`).
    """
    segments, colours = [], []
    for foot_x, foot_y, row, col, loss in zip(
        chosen.foot_x, chosen.foot_y, chosen.row, chosen.col, chosen.loss, strict=True
    ):
        x, y = np.asarray(foot_x, dtype=float), np.asarray(foot_y, dtype=float)
        keep = np.isfinite(x) & np.isfinite(y)
        if not keep.any():
            continue
        size = max(np.ptp(x[keep]), np.ptp(y[keep]))
        scale = 0.8 / size if size > 0 else 1.0
        cx, cy = (x[keep].max() + x[keep].min()) / 2, (y[keep].max() + y[keep].min()) / 2
        points = np.column_stack([col + 0.5 + (x - cx) * scale, row + 0.5 + (y - cy) * scale])
        for run in assembled_runs(keep):
            segments.append(points[run])
            colours.append(float(loss))
        ax.text(col + 0.96, row + 0.04, f"{size:.1f}", ha="right", va="bottom", fontsize=label_size)
    lines = LineCollection(segments, cmap=PATH_CMAP, norm=norm, linewidths=0.9)
    lines.set_array(np.array(colours))
    ax.add_collection(lines)
    rows, cols = shape
    ax.vlines(np.arange(1, cols), 0, rows, color="0.85", lw=0.5)
    ax.hlines(np.arange(1, rows), 0, cols, color="0.85", lw=0.5)
    ax.set_xlim(0, cols)
    ax.set_ylim(0, rows)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_aspect("equal")
    return lines


def assembled_runs(keep: np.ndarray) -> list[np.ndarray]:
    """Returns the index runs of consecutive assembled crank angles of a cyclic path
    (keep: (A,) bool), each to draw as one line: the whole turn closed when every angle
    assembles, else each run on its own (a run through the last angle continues into the
    first)."""
    n = len(keep)
    if keep.all():
        return [np.append(np.arange(n), 0)]
    start = int(np.flatnonzero(~keep)[0])  # begin at a gap, so no run wraps unseen
    order = (np.arange(n) + start) % n
    runs, current = [], []
    for i in order:
        if keep[i]:
            current.append(i)
        elif current:
            runs.append(np.array(current))
            current = []
    if current:
        runs.append(np.array(current))
    return [r for r in runs if len(r) > 1]


def view_frame(view: dict[str, np.ndarray]) -> pd.DataFrame:
    """Returns an optimizer's `view()` as the archive table the drawings read (2-D
    columns become one array per row, as parquet reads them back)."""
    return pd.DataFrame({k: list(v) if np.ndim(v) == 2 else v for k, v in view.items()})


def draw_trial_maps(view: dict[str, np.ndarray], approach: str, path: Path) -> None:
    """Draws one trial's final repertoire or population to a PNG at `path`, atomically.

    With a grid (MAP-Elites, RANDOM): the best loss of every filled cell (4-D maps folded
    as in the report) beside the 5 x 5 path map; otherwise the five paths the report draws
    for the approach.
    """
    archive = view_frame(view)
    bins = bin_columns(archive.columns)
    # RANDOM keeps a 2-D grid (MAP-LIS's by default): its paths are mapped as that grid's.
    chosen = select_paths(archive, approach if is_map_elites(approach) or not bins else "MAP-LIS")
    # Fixed axes, no layout engine: a layout pass costs more than the drawing itself.
    norm = loss_norm(archive.loss.to_numpy(dtype=float))
    if bins:
        fig = Figure(figsize=(8.0, 4.0))
        heat = fig.add_axes((0.06, 0.12, 0.35, 0.78))
        bar = fig.add_axes((0.43, 0.18, 0.012, 0.66))
        paths = fig.add_axes((0.54, 0.08, 0.42, 0.82))
        space = space_of(approach, len(bins))
        rows, cols, side = fold_bins(archive[bins].to_numpy(), space.resolution)
        image = np.full((side, side), np.nan)
        image[rows, cols] = archive.loss.to_numpy(dtype=float)
        shown = heat.imshow(image, origin="lower", cmap=LOSS_CMAP, norm=norm)
        heat.set_title(f"{approach}: best loss per cell ({len(archive)} filled)", fontsize=8)
        heat.tick_params(labelsize=6)
        x_axis, y_axis = axis_names(space)
        heat.set_xlabel(f"{x_axis} (bin)", fontsize=6)
        heat.set_ylabel(f"{y_axis} (bin)", fontsize=6)
        colour_bar = fig.colorbar(shown, cax=bar, extend="max")
        colour_bar.set_label(LOSS_LABEL, fontsize=6)
        colour_bar.ax.tick_params(labelsize=6)
        paths.set_title(f"best path per region ({DOWNSAMPLED} x {DOWNSAMPLED})", fontsize=8)
        shape = (DOWNSAMPLED, DOWNSAMPLED)
    else:
        fig = Figure(figsize=(6.0, 1.8))
        paths = fig.add_axes((0.02, 0.04, 0.96, 0.8))
        paths.set_title(f"{approach}: {STRIP_PATHS} paths of the final population", fontsize=8)
        shape = (1, STRIP_PATHS)
    draw_paths(paths, chosen, shape, norm)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110)
