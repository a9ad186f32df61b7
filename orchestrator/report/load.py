"""Provides `load_grid`: one grid's trial runs, metric histories and archives as pandas;
and `merge_grids`: several grids of one study as one."""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.orchestrator.config import EXECUTION_KEYS, ConfigError, from_dict
from linkevo.sim.errors import LinkevoError
from linkevo.sim.study import APPROACHES, FITNESSES, ordered
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.runs import NotFound, RunStore, latest_per_trial

HISTORY_COLUMNS: tuple[str, ...] = (
    "iteration",
    "evaluations",
    "best_loss",
    "mean_loss",
    "coverage",
    "qd_score",
    "common_coverage",
    "common_qd_score",
    "hypervolume",
)
FINAL_MEASURES: tuple[str, ...] = ("common_coverage", "common_qd_score", "path_diversity")
"""Per-trial measures read as their last logged value: coverage and QD-score of every
evaluated genome on the common MAP-LIS grid (`algorithms.common_grid`), and the diversity
of the best paths (`sim.linkage.path_diversity`); NaN for a trial that did not log them."""
WALK_MEASURES: tuple[str, ...] = (
    "best_flat_cm",
    "best_carpet_cm",
    "best_full_flat_cm",
    "best_full_carpet_cm",
    "best_models_agree",
    "best_chaotic",
    "best_slides",
    "best_leg_width_cm",
    "best_stroke_cm",
    "best_crank_share",
)
"""A walking trial's (fitness F_w) best walker as it ends: its credited distance per floor
on the lean model, on the full model from hand-placed starts, whether the two agree, its
repeats scatter or its feet slide, and its leg's shape (`workers.trial_walks`); NaN for
other trials and for a best that does not walk soundly."""
ARCHIVE_FILES: tuple[str, ...] = (layout.REPERTOIRE, layout.POPULATION)
STATUS_MISSING = "MISSING"
DOWNLOAD_THREADS = 8


@dataclass(frozen=True)
class GridData:
    """Everything a report needs from one grid, read from MLflow.

    Attributes:
        grid_id: the grid's id (tag `grid_id`).
        parent_run_id: the grid's parent run, where the report is logged.
        tracking_uri: the store it was read from.
        config: the grid's resolved config (`grid_config.json`).
        trials: one row per trial (expected by the config or seen in MLflow), columns
            trial_key, approach, fitness, trial_index, seed, run_id, status (FINISHED,
            FAILED, KILLED, RUNNING or MISSING), error, best_loss (the best-ever loss, the
            last logged value), coverage and qd_score (last logged; the approach's own grid
            for MAP-Elites, the current population on the MAP-LIS grid for EA and NSGA-II,
            RANDOM's samples on it), the `FINAL_MEASURES` and `WALK_MEASURES`, all NaN
            unless FINISHED with metrics, final_evaluations, archive (local parquet path or
            None), best_linkage (local path of the best-ever linkage document, or None).
        history: long table, one row per trial and iteration: trial_key, approach,
            fitness, status and the HISTORY_COLUMNS present in the runs (NaN where a run
            did not log one).
    """

    grid_id: str
    parent_run_id: str
    tracking_uri: str
    config: dict
    trials: pd.DataFrame
    history: pd.DataFrame

    def finished(self) -> pd.DataFrame:
        """Returns the FINISHED trials with a best loss (the ones statistics use)."""
        return finished_trials(self.trials)

    def approaches(self) -> list[str]:
        """Returns the grid's approaches in the study's order."""
        return ordered(self.trials.approach.unique(), APPROACHES)

    def fitnesses(self) -> list[str]:
        """Returns the grid's fitness functions in the study's order."""
        return ordered(self.trials.fitness.unique(), FITNESSES)


def finished_trials(trials: pd.DataFrame) -> pd.DataFrame:
    """Returns the FINISHED trials with a best loss of a trials table (a grid's, or a
    report's `trials.csv`), the ones statistics use."""
    done = trials[(trials.status == "FINISHED") & trials.best_loss.notna()]
    return done.reset_index(drop=True)


def load_grid(
    tracking_uri: str,
    grid_id: str | None,
    cache_dir: Path,
    experiment: str = "linkevo",
    first_trials: int | None = None,
) -> GridData:
    """Returns one grid's runs, histories and archive paths (`grid_id` None: the latest);
    with `first_trials` = N, only trial indices below N (the config then says N trials).

    One paged search lists the trials; each trial's `metrics.csv` and archive
    parquet are read straight from a file-based artefact store, otherwise downloaded in
    parallel into `cache_dir`. A trial without `metrics.csv` (a failed one, say) falls
    back to its logged metric histories.
    """
    store = RunStore(tracking_uri, experiment)
    grid_id, parent_id = store.grid(grid_id)
    runs = store.trial_table(grid_id)
    parent = store.run(parent_id)
    config = _grid_config(store, parent, cache_dir)
    runs = latest_per_trial(runs)
    if first_trials is not None and len(runs):
        index = pd.to_numeric(runs.get(f"tags.{layout.TRIAL_INDEX}"), errors="coerce")
        runs = runs[index < first_trials].reset_index(drop=True)
        config = {**config, "trials": min(int(config.get("trials", first_trials)), first_trials)}
    with ThreadPoolExecutor(DOWNLOAD_THREADS) as pool:
        fetched = list(
            pool.map(
                lambda row: _fetch_trial(store, row, cache_dir),
                [row for _, row in runs.iterrows()],
            )
        )
    histories = [h for h, _, _ in fetched]
    trials = _trial_table(runs, histories, [a for _, a, _ in fetched], [b for _, _, b in fetched])
    history = _history_table(trials, histories)
    trials = _add_missing(trials, config)
    if trials.empty:
        raise NotFound(f"grid {grid_id!r} has no trial runs and no config naming any")
    return GridData(
        grid_id=grid_id,
        parent_run_id=parent_id,
        tracking_uri=tracking_uri,
        config=config,
        trials=trials,
        history=history,
    )


class GridsDiffer(LinkevoError, ValueError):
    """Grids that are not parts of one study (their configs differ beyond what they run)."""


SPLIT_KEYS: frozenset[str] = frozenset({"approaches", "fitnesses", "trials"})
"""Config keys in which grids that make one study may differ: a study split into grids by
approach or fitness (on several machines, say), or grown apart."""


def merge_grids(grids: list[GridData]) -> GridData:
    """Returns several grids as one study, reported together: their trials and histories
    side by side, the config of the first with every grid's approaches and fitnesses and
    the most trials; the grid id joins theirs with "+", the report is logged in the
    first grid's parent run.

    Raises:
        GridsDiffer: naming the key and values, when two configs differ in a key that
            changes what a trial computes (any but `SPLIT_KEYS` and `EXECUTION_KEYS`),
            or naming the trial, when one trial key is in two grids.
    """
    first = grids[0]
    if len(grids) == 1:
        return first
    ignored = SPLIT_KEYS | EXECUTION_KEYS
    for grid in grids[1:]:
        for key in sorted((set(first.config) | set(grid.config)) - ignored):
            if first.config.get(key) != grid.config.get(key):
                raise GridsDiffer(
                    f"grids {first.grid_id} and {grid.grid_id} differ in {key} "
                    f"({first.config.get(key)!r} against {grid.config.get(key)!r}); allowed: "
                    "grids that differ only in approaches, fitnesses and trials"
                )
    trials = pd.concat([g.trials for g in grids], ignore_index=True)
    twice = trials.trial_key[trials.trial_key.duplicated()]
    if len(twice):
        raise GridsDiffer(
            f"trial {twice.iloc[0]} is in more than one of the grids; allowed: grids with "
            "different approaches or fitnesses"
        )
    config = {
        **first.config,
        "approaches": ordered(trials.approach.unique(), APPROACHES),
        "fitnesses": ordered(trials.fitness.unique(), FITNESSES),
        "trials": max(int(g.config.get("trials", 0)) for g in grids),
    }
    return GridData(
        grid_id="+".join(g.grid_id for g in grids),
        parent_run_id=first.parent_run_id,
        tracking_uri=first.tracking_uri,
        config=config,
        trials=trials,
        history=pd.concat([g.history for g in grids], ignore_index=True),
    )


def _grid_config(store: RunStore, parent, cache_dir: Path) -> dict:
    """Returns the parent run's `grid_config.json` ({} when the run has none)."""
    name = layout.GRID_CONFIG_JSON
    path = store.artefact_at(parent.info.artifact_uri, name, cache_dir / "grid")
    return json.loads(path.read_text()) if path is not None else {}


def _fetch_trial(
    store: RunStore, row: pd.Series, cache_dir: Path
) -> tuple[pd.DataFrame, Path | None, Path | None]:
    """Returns (metric history, local archive path, local best-linkage path) of one trial
    run; a path is None where the run has no such file."""
    folder = cache_dir / row.run_id
    csv = store.artefact_at(row.artifact_uri, layout.METRICS_FILE, folder)
    history = pd.read_csv(csv) if csv is not None else _history_from_metrics(store, row)
    archive = None
    for name in ARCHIVE_FILES:
        archive = store.artefact_at(row.artifact_uri, name, folder)
        if archive is not None:
            break
    return history, archive, store.artefact_at(row.artifact_uri, layout.BEST_JSON, folder)


def _history_from_metrics(store: RunStore, row: pd.Series) -> pd.DataFrame:
    """Returns a trial's history from its logged metrics (step = iteration)."""
    names = [c.removeprefix("metrics.") for c in row.index if c.startswith("metrics.")]
    series = {}
    for name in names:
        if name in HISTORY_COLUMNS and name != "iteration" and pd.notna(row[f"metrics.{name}"]):
            points = store.metric_history(row.run_id, name)
            series[name] = pd.Series(points, dtype=float)
    if not series:
        return pd.DataFrame(columns=["iteration"])
    table = pd.DataFrame(series).sort_index()
    return table.rename_axis("iteration").reset_index()


def _trial_table(
    runs: pd.DataFrame,
    histories: list[pd.DataFrame],
    archives: list[Path | None],
    best_linkages: list[Path | None],
) -> pd.DataFrame:
    """Returns one row per seen trial with its status and best loss."""

    def tag(name: str) -> pd.Series:
        column = f"tags.{name}"
        return runs[column] if column in runs else pd.Series([None] * len(runs), dtype=object)

    def last(name: str) -> list[float]:
        """The last logged value of metric `name` per trial (NaN where never logged)."""
        return [
            float(h[name].dropna().iloc[-1]) if name in h and h[name].notna().any() else np.nan
            for h in histories
        ]

    def final(name: str) -> list[float]:
        """A measure logged once at the end (the run's value), else its last row."""
        column = f"metrics.{name}"
        logged = runs[column].astype(float).tolist() if column in runs else [np.nan] * len(runs)
        return [v if np.isfinite(v) else h for v, h in zip(logged, last(name), strict=True)]

    evals = [
        float(h.evaluations.max()) if "evaluations" in h and len(h) else np.nan for h in histories
    ]
    table = pd.DataFrame(
        {
            "trial_key": tag(layout.TRIAL_KEY).astype(object),
            "approach": tag(layout.APPROACH).astype(object),
            "fitness": tag(layout.FITNESS).astype(object),
            "trial_index": pd.to_numeric(tag(layout.TRIAL_INDEX), errors="coerce"),
            "seed": pd.to_numeric(tag(layout.SEED), errors="coerce"),
            "run_id": runs.run_id.astype(object),
            "status": runs.status.astype(object),
            "error": tag(layout.ERROR).astype(object),
            "best_loss": last("best_loss"),  # best-ever: the last value is the lowest
            "coverage": last("coverage"),
            "qd_score": last("qd_score"),
            **{name: final(name) for name in (*FINAL_MEASURES, *WALK_MEASURES)},
            "final_evaluations": evals,
            "archive": [str(a) if a is not None else None for a in archives],
            "best_linkage": [str(b) if b is not None else None for b in best_linkages],
        }
    )
    measures = ["best_loss", "coverage", "qd_score", *FINAL_MEASURES, *WALK_MEASURES]
    table.loc[table.status != "FINISHED", measures] = np.nan
    return table


def _expected_cells(config: dict) -> list[tuple[str, str, int]] | None:
    """Returns the (approach, fitness, trial_index) cells the config asks for, if it parses."""
    try:
        cfg = from_dict(config, source=layout.GRID_CONFIG_JSON)
    except (ConfigError, TypeError):
        return None
    return [(a, f, i) for a in cfg.approaches for f in cfg.fitnesses for i in range(cfg.trials)]


def _add_missing(trials: pd.DataFrame, config: dict) -> pd.DataFrame:
    """Returns `trials` plus a MISSING row for each cell the config expects but MLflow lacks."""
    cells = _expected_cells(config)
    if cells is None:
        return trials
    seen = set(zip(trials.approach, trials.fitness, trials.trial_index.astype(float), strict=True))
    rows = [
        {
            "trial_key": layout.trial_key(a, f, i),
            "approach": a,
            "fitness": f,
            "trial_index": i,
            "status": STATUS_MISSING,
            "best_loss": np.nan,
            "final_evaluations": np.nan,
        }
        for a, f, i in cells
        if (a, f, float(i)) not in seen
    ]
    if not rows:
        return trials
    missing = pd.DataFrame(rows).reindex(columns=trials.columns)
    return pd.concat([trials.astype(object), missing.astype(object)], ignore_index=True).astype(
        {
            "best_loss": float,
            "coverage": float,
            "qd_score": float,
            **dict.fromkeys((*FINAL_MEASURES, *WALK_MEASURES), float),
            "final_evaluations": float,
            "trial_index": float,
        }
    )


def _history_table(trials: pd.DataFrame, histories: list[pd.DataFrame]) -> pd.DataFrame:
    """Returns all trials' histories stacked, with trial identity columns (row-aligned)."""
    frames = []
    for meta, history in zip(trials.itertuples(), histories, strict=True):
        if history.empty:
            continue
        frame = history.reindex(columns=list(HISTORY_COLUMNS))
        frame.insert(0, "trial_key", meta.trial_key)
        frame.insert(1, "approach", meta.approach)
        frame.insert(2, "fitness", meta.fitness)
        frame.insert(3, "status", meta.status)
        frames.append(frame)
    columns = ["trial_key", "approach", "fitness", "status", *HISTORY_COLUMNS]
    if not frames:
        return pd.DataFrame(columns=columns)
    return pd.concat(frames, ignore_index=True).astype({c: float for c in HISTORY_COLUMNS})


def read_archive(path: str | os.PathLike, columns: Iterable[str] | None = None) -> pd.DataFrame:
    """Returns the archive parquet at `path`, only the `columns` present when given."""
    import pyarrow.parquet as pq

    if columns is None:
        return pq.read_table(path).to_pandas()
    present = set(pq.read_schema(path).names)
    return pq.read_table(path, columns=[c for c in columns if c in present]).to_pandas()


def read_archives(paths: Iterable[str], columns: Iterable[str]) -> list[pd.DataFrame]:
    """Returns `read_archive(path, columns)` of every path, read on a thread pool."""
    columns = list(columns)
    with ThreadPoolExecutor(DOWNLOAD_THREADS) as pool:
        return list(pool.map(lambda path: read_archive(path, columns), paths))
