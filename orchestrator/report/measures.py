"""Provides `trial_measures` and `best_path_sizes`: per-trial numbers some of the study's
claims are judged on, beyond the ones each trial logs (best loss, coverage, common grid,
path diversity)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import chatterjeexi, spearmanr

from linkevo.algorithms.pareto import non_dominated_ranks
from linkevo.orchestrator.report.load import GridData, read_archive
from linkevo.sim.study import is_map_elites, is_pareto
from linkevo.workers.store.artifacts import read_document


def stagnation(history: pd.DataFrame) -> float:
    """Returns the share of a trial's evaluations spent after its last best-loss
    improvement (0: still improving at the end; near 1: stuck early), from its
    history rows (evaluations, best_loss)."""
    rows = history[history.best_loss.notna()].sort_values("evaluations")
    if rows.empty:
        return np.nan
    improved = rows.evaluations[rows.best_loss.diff().fillna(-1.0) < 0].iloc[-1]
    total = rows.evaluations.iloc[-1]
    return float((total - improved) / total)


def descriptor_correlation(archive: pd.DataFrame) -> float:
    """Returns the largest |Spearman rho| between one of a repertoire's descriptors and its
    elites' loss: how far the map's dimensions say what the fitness says."""
    desc = [c for c in archive.columns if c.startswith("desc_")]
    finite = archive[np.isfinite(archive.loss)]
    if len(finite) < 3 or not desc:
        return np.nan
    rhos = [abs(spearmanr(finite[c], finite.loss).statistic) for c in desc]
    return float(np.nanmax(rhos)) if np.isfinite(rhos).any() else np.nan


def descriptor_dependence(archive: pd.DataFrame) -> float:
    """Returns the largest Chatterjee xi of a repertoire's elites' loss on one of its
    descriptors (scipy's `chatterjeexi`): 0 when the loss does not depend on it, 1 when
    the loss is a function of it, whether monotone or peaked (a path of a certain size
    scores best), where Spearman's rho sees only the monotone part."""
    desc = [c for c in archive.columns if c.startswith("desc_")]
    finite = archive[np.isfinite(archive.loss)]
    if len(finite) < 3 or not desc:
        return np.nan
    xis = [chatterjeexi(finite[c], finite.loss).statistic for c in desc]
    return float(np.nanmax(xis)) if np.isfinite(xis).any() else np.nan


def front_size(archive: pd.DataFrame) -> float:
    """Returns the number of distinct mutually non-dominated (loss_0, loss_1) points of a
    two-objective population."""
    losses = archive[["loss_0", "loss_1"]].to_numpy(dtype=float)
    losses = np.unique(losses[np.isfinite(losses).all(axis=1)], axis=0)
    return float((non_dominated_ranks(losses) == 0).sum()) if len(losses) else np.nan


def trial_measures(grid: GridData) -> pd.DataFrame:
    """Returns the finished trials (`GridData.finished`) with four measures added:
    stagnation (every approach), descriptor_correlation and descriptor_dependence
    (MAP-Elites repertoires) and front_size (NSGA-II populations); NaN where a measure does
    not apply or its data is missing."""
    trials = grid.finished().copy()
    history = grid.history
    trials["stagnation"] = [
        stagnation(history[history.trial_key == key]) for key in trials.trial_key
    ]
    correlation, dependence, fronts = [], [], []
    for trial in trials.itertuples():
        has = isinstance(trial.archive, str)
        if has and is_map_elites(trial.approach):
            archive = read_archive(trial.archive, ["loss", *(f"desc_{d}" for d in range(4))])
            correlation.append(descriptor_correlation(archive))
            dependence.append(descriptor_dependence(archive))
        else:
            correlation.append(np.nan)
            dependence.append(np.nan)
        if has and is_pareto(trial.approach):
            fronts.append(front_size(read_archive(trial.archive, ["loss_0", "loss_1"])))
        else:
            fronts.append(np.nan)
    trials["descriptor_correlation"] = correlation
    trials["descriptor_dependence"] = dependence
    trials["front_size"] = fronts
    return trials


def best_path_sizes(grid: GridData) -> pd.DataFrame:
    """Returns the size of each finished trial's best-ever foot path, read from its
    best-linkage document, in model units (`../shared/spec`: 8 mm a module).

    Returns:
        Columns trial_key, approach, fitness, width, height, size (the larger of the two),
        failed_angles (the linkage's crank angles that do not assemble; the path skips
        them, which is how F_sl's best linkages reach their size, docs/results.md).
    """
    trials = grid.finished()
    rows = []
    for trial in trials[trials.best_linkage.notna()].itertuples():
        doc = read_document(Path(trial.best_linkage))
        path = doc["foot_path"]
        x, y = np.array(path["x"], dtype=float), np.array(path["y"], dtype=float)  # None: NaN
        if np.isfinite(x).any():
            width, height = np.nanmax(x) - np.nanmin(x), np.nanmax(y) - np.nanmin(y)
            size = max(width, height)
            key = (trial.trial_key, trial.approach, trial.fitness)
            rows.append((*key, width, height, size, int(doc["error"])))
    columns = ["trial_key", "approach", "fitness", "width", "height", "size", "failed_angles"]
    return pd.DataFrame(rows, columns=columns)
