"""Provides `draw_walk_map`: a repertoire's walk map, the distance each walked cell's robot
walks in 10 s, a panel per floor, in the folded map layout of the loss maps
(`workers.store.tables.fold_bins`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure

from linkevo.sim.robot.hexapod import in_floor_order
from linkevo.sim.robot.walk_rows import Status
from linkevo.workers.store.artifacts import atomic_path
from linkevo.workers.store.tables import axis_names, bin_columns, fold_bins, space_of

DISTANCE_CMAP = "viridis"
"""Far walkers bright yellow, short ones dark purple: brighter is better, as on the loss maps."""
BROKEN = ListedColormap(["#e34a33"])
"""Cells whose robot breaks, in one red."""


def draw_walk_map(frame: pd.DataFrame, approach: str, name: str, path: Path) -> Path:
    """Draws the walk map (`sim.robot.walk_rows.COLUMNS` rows with the cells' bins) to a PNG at
    `path`, atomically, and returns the path.

    Args:
        frame: a row per cell and floor.
        approach: the repertoire's approach (its grid); name: the trial, for the title.
    """
    bins = bin_columns(frame.columns)
    space = space_of(approach, len(bins))
    floors = in_floor_order(frame["floor"].unique())
    walked = frame[frame["status"] == Status.WALKED]
    top = walked.loc[~walked["breaks"], "mean_distance_cm"]
    high = max(float(np.nanquantile(top, 0.98)), 1.0) if top.notna().any() else 1.0
    low = min(float(np.nanquantile(top, 0.02)), 0.0) if top.notna().any() else 0.0
    fig = Figure(figsize=(4.0 * len(floors) + 0.8, 4.2))
    width = 0.84 / len(floors)
    shown = None
    for k, floor in enumerate(floors):
        ax = fig.add_axes((0.06 + k * (width + 0.02), 0.12, width - 0.04, 0.76))
        part = walked[walked["floor"] == floor]
        rows, cols, side = fold_bins(part[bins].to_numpy(), space.resolution)
        distance = np.full((side, side), np.nan)
        broken = np.full((side, side), np.nan)
        ok = ~part["breaks"].to_numpy(dtype=bool)
        distance[rows[ok], cols[ok]] = part["mean_distance_cm"].to_numpy(dtype=float)[ok]
        broken[rows[~ok], cols[~ok]] = 1.0
        shown = ax.imshow(distance, origin="lower", cmap=DISTANCE_CMAP, vmin=low, vmax=high)
        ax.imshow(broken, origin="lower", cmap=BROKEN, vmin=0.0, vmax=1.0)
        beyond = int(
            (
                part["mean_distance_cm"].to_numpy(dtype=float)[ok]
                > part["bound_cm"].to_numpy(dtype=float)[ok]
            ).sum()
        )
        ax.set_title(
            f"{floor}: {int(ok.sum())} walk ({beyond} beyond the level-body bound), "
            f"{int((~ok).sum())} break (red)",
            fontsize=8,
        )
        x_axis, y_axis = axis_names(space)
        ax.set_xlabel(f"{x_axis} (bin)", fontsize=6)
        ax.set_ylabel(f"{y_axis} (bin)", fontsize=6)
        ax.tick_params(labelsize=6)
    bar = fig.add_axes((0.9, 0.18, 0.015, 0.64))
    colour_bar = fig.colorbar(shown, cax=bar, extend="both")
    seconds = float(frame["seconds"].max()) if len(frame) else 10.0
    colour_bar.set_label(
        f"distance in {seconds:g} s, cm (brighter is further; below 0: backwards)", fontsize=6
    )
    colour_bar.ax.tick_params(labelsize=6)
    fig.suptitle(f"{name}: walk map (simulated robot, one walk per cell)", fontsize=9)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=130)
    return path
