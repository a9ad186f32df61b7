"""Provides the physical checks (`sim.linkage.physical`) of a grid's best linkages, per trial and
per approach and fitness: which of the study's answers a builder could build as simulated;
and, for walking trials, what their best walkers are (`walking_winners`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.orchestrator.report.load import WALK_MEASURES, GridData
from linkevo.sim import decode, simulate
from linkevo.sim.linkage.linkage_doc import DocumentError, from_document
from linkevo.sim.linkage.physical import physical_checks
from linkevo.sim.study import DEFAULT_ANGLES, WALKING_FITNESS
from linkevo.workers.store.artifacts import read_document
from linkevo.workers.store.runs import in_study_order

TRIAL_CHECK_COLUMNS: tuple[str, ...] = (
    "trial_key",
    "approach",
    "fitness",
    "best_loss",
    "buildable",
    "turns_fully",
    "min_transmission_deg",
    "toggle_passages",
    "max_stretch",
    "size_modules",
)


def best_linkage_checks(grid: GridData) -> pd.DataFrame:
    """Returns the checks of each finished trial's best-ever linkage (its document).

    Returns:
        TRIAL_CHECK_COLUMNS, one row per finished trial with a readable best-linkage
        document; size_modules is the larger of the swept box's width and height.
    """
    trials = grid.finished()
    trials = trials[trials.best_linkage.notna()].reset_index(drop=True)
    decoded = [_read(path) for path in trials.best_linkage]
    trials = trials[[d is not None for d in decoded]].reset_index(drop=True)
    decoded = [d for d in decoded if d is not None]
    if trials.empty:
        return pd.DataFrame(columns=list(TRIAL_CHECK_COLUMNS))
    n_angles = int(grid.config.get("n_angles", DEFAULT_ANGLES))
    parts = []
    for mode in sorted({mode for _, mode in decoded}):
        rows = [i for i, (_, m) in enumerate(decoded) if m == mode]
        batch = decode(np.stack([decoded[i][0] for i in rows]), mode)
        checks = physical_checks(batch, simulate(batch, n_angles))
        parts.append(
            pd.DataFrame(
                {
                    "row": rows,
                    "buildable": checks.buildable,
                    "turns_fully": checks.turns_fully,
                    "min_transmission_deg": checks.min_transmission_deg,
                    "toggle_passages": checks.toggle_passages,
                    "max_stretch": checks.max_stretch,
                    "size_modules": checks.size_modules.max(axis=1),
                }
            )
        )
    found = pd.concat(parts).sort_values("row").set_index("row")
    return pd.concat([trials[["trial_key", "approach", "fitness", "best_loss"]], found], axis=1)


def _read(path: str) -> tuple[np.ndarray, str] | None:
    """Returns (genome, mode) of a linkage document, or None when it is not one."""
    try:
        return from_document(read_document(Path(path)))
    except DocumentError:
        return None


def walking_winners(grid: GridData) -> pd.DataFrame:
    """Returns each finished walking trial's best walker (trial_key, approach, fitness and
    the `WALK_MEASURES`), in the study's order; empty for a grid without walking trials."""
    columns = ["trial_key", "approach", "fitness", *WALK_MEASURES]
    trials = grid.finished()
    trials = trials[trials.fitness == WALKING_FITNESS]
    return in_study_order(trials.reindex(columns=columns)).reset_index(drop=True)


def checks_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Returns, per approach and fitness (in the study's order), how many best linkages
    are buildable and the medians of their transmission angle, stretch and size."""
    table = in_study_order(table)
    grouped = table.groupby(["approach", "fitness"], sort=False)
    return grouped.agg(
        trials=("trial_key", "size"),
        buildable=("buildable", "sum"),
        turn_fully=("turns_fully", "sum"),
        median_min_transmission_deg=("min_transmission_deg", "median"),
        median_max_stretch=("max_stretch", "median"),
        median_size_modules=("size_modules", "median"),
    ).reset_index()
