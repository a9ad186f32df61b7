"""Provides the grid's parent run: created once and reused on resume, described for the
MLflow UI, and given each cell's summary metrics."""

from __future__ import annotations

import socket
import statistics
import time

from mlflow.entities import Metric, Param
from mlflow.tracking import MlflowClient

from linkevo.orchestrator.config import GridConfig, flatten, to_toml
from linkevo.orchestrator.grid import Grid
from linkevo.workers.store import run_layout as layout
from linkevo.workers.trial_task import TrialOutcome


def parent_run(client: MlflowClient, experiment_id: str, grid: Grid) -> str:
    """Returns the grid's parent run id, reusing an earlier launch's run on resume."""
    existing = layout.search(  # the first launch's run, which every resume reuses
        client,
        [experiment_id],
        layout.where(layout.GRID, **{layout.GRID_ID: grid.grid_id}),
        order_by=["attributes.start_time ASC"],
        limit=1,
    )
    if existing:
        first = existing[0]
        run_id = first.info.run_id
        client.update_run(run_id, status="RUNNING")
        if layout.ERROR in first.data.tags:  # the error of a launch that is over
            client.delete_tag(run_id, layout.ERROR)
        return run_id
    tags = {
        layout.KIND: layout.GRID,
        layout.GRID_ID: grid.grid_id,
        layout.CODE_VERSION: grid.code_version,
        layout.HOST: socket.gethostname(),
        layout.NOTE: grid_description(grid),
    }
    run_id = client.create_run(experiment_id, run_name=f"grid-{grid.grid_id}", tags=tags)
    run_id = run_id.info.run_id
    params = [Param(k, v) for k, v in flatten(grid.config.to_dict()).items()]
    for start in range(0, len(params), 100):
        client.log_batch(run_id, params=params[start : start + 100])
    client.log_dict(run_id, grid.config.to_dict(), layout.GRID_CONFIG_JSON)
    client.log_text(run_id, to_toml(grid.config), layout.GRID_CONFIG_TOML)
    return run_id


def cell_summaries(config: GridConfig, outcomes: tuple[TrialOutcome, ...]) -> dict[str, float]:
    """Returns the grid parent's summary metrics: per approach and fitness, over the
    FINISHED trials, `<approach>/<fitness>/best_loss_median`, `.../best_loss_min`,
    `.../coverage_median`, `.../qd_score_median` and `.../finished` (a count)."""
    metrics: dict[str, float] = {}
    for approach in config.approaches:
        for fitness in config.fitnesses:
            cell = [
                o
                for o in outcomes
                if layout.parse_trial_key(o.trial_key)[:2] == (approach, fitness)
                and o.status == "FINISHED"
            ]
            prefix = f"{approach}/{fitness}"
            metrics[f"{prefix}/finished"] = float(len(cell))
            for name in ("best_loss", "coverage", "qd_score"):
                values = [getattr(o, name) for o in cell if getattr(o, name) is not None]
                if values:
                    metrics[f"{prefix}/{name}_median"] = float(statistics.median(values))
                if values and name == "best_loss":
                    metrics[f"{prefix}/best_loss_min"] = float(min(values))
    return metrics


def log_cell_summaries(
    client: MlflowClient, run_id: str, config: GridConfig, outcomes: tuple[TrialOutcome, ...]
) -> None:
    """Logs `cell_summaries` to the grid's parent run, so the MLflow UI's runs table shows
    each cell's numbers next to the grid (a resumed grid logs them again, updated)."""
    metrics = [
        Metric(key, value, int(time.time() * 1000), 0)
        for key, value in cell_summaries(config, outcomes).items()
    ]
    for start in range(0, len(metrics), 1000):
        client.log_batch(run_id, metrics=metrics[start : start + 1000])


def grid_description(grid: Grid) -> str:
    """Returns the parent run's description (MLflow's `mlflow.note.content`, Markdown):
    what the grid runs, its budget and how to read the results."""
    cfg = grid.config
    return (
        f"**linkevo grid `{grid.grid_id}`** ({len(grid.cells)} trials): "
        f"{', '.join(cfg.approaches)} × {', '.join(cfg.fitnesses)}, {cfg.trials} trial(s) "
        f"each; {cfg.evaluations:,} evaluations per trial in batches of {cfg.batch_size:,}; "
        f"mode `{cfg.mode}`, target `{cfg.target}`, grid seed {cfg.seed}; code "
        f"`{grid.code_version}`.\n\n"
        "The nested runs are the trials (metrics per iteration, the final repertoire or "
        "population, the best linkage). This run's metrics summarise each approach and "
        "fitness: `<approach>/<fitness>/best_loss_median`, `best_loss_min`, "
        "`coverage_median`, `qd_score_median`.\n\n"
        f"Figures and statistics: `linkevo report {grid.grid_id}` (also logged here under "
        f"`report/`). A trial's linkage: `linkevo pull RUN_ID`, or `linkevo pull "
        f"{grid.grid_id} --best --fitness {cfg.fitnesses[0]}`. Resolved config: "
        "`grid_config.toml`."
    )
