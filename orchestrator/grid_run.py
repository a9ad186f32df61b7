"""Provides the grid's parent run: created once and reused on resume, described for the
MLflow UI, and given the summary of each approach and fitness."""

from __future__ import annotations

import socket
import statistics

from linkevo.orchestrator.config import GridConfig, flatten, to_toml
from linkevo.orchestrator.grid import Grid
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.runs import RunStore
from linkevo.workers.trial_task import TrialOutcome


def parent_run(store: RunStore, grid: Grid) -> str:
    """Returns the grid's parent run id, reusing an earlier launch's run on resume."""
    existing = store.grid_runs(grid.grid_id, first=True, limit=1)  # what every resume reuses
    if existing:
        first = existing[0]
        run_id = first.info.run_id
        store.set_running(run_id)
        if layout.ERROR in first.data.tags:  # the error of a launch that is over
            store.delete_tag(run_id, layout.ERROR)
        if first.data.tags.get(layout.TRIALS) != str(grid.config.trials):  # extended
            store.set_tag(run_id, layout.TRIALS, str(grid.config.trials))
            store.log_document(run_id, grid.config.to_dict(), layout.GRID_CONFIG_JSON)
            store.log_text(run_id, to_toml(grid.config), layout.GRID_CONFIG_TOML)
        return run_id
    tags = {
        layout.KIND: layout.GRID,
        layout.GRID_ID: grid.grid_id,
        layout.TRIALS: str(grid.config.trials),
        layout.CODE_VERSION: grid.code_version,
        layout.HOST: socket.gethostname(),
        layout.NOTE: grid_description(grid),
    }
    run_id = store.create_run(f"grid-{grid.grid_id}", tags)
    # `trials` is a tag, not a param: an extended grid's count changes, a param cannot.
    params = {k: v for k, v in flatten(grid.config.to_dict()).items() if k != "trials"}
    store.log_params(run_id, params)
    store.log_document(run_id, grid.config.to_dict(), layout.GRID_CONFIG_JSON)
    store.log_text(run_id, to_toml(grid.config), layout.GRID_CONFIG_TOML)
    return run_id


SUMMARY_COLUMNS = (
    "approach",
    "fitness",
    "finished",
    "trials",
    "best_loss_min",
    "best_loss_median",
    "coverage_median",
    "qd_score_median",
)
"""The grid summary's columns: per approach and fitness, the trials FINISHED of those
run, and the best loss (min, median), coverage and QD-score (medians) over the finished
ones (None where no finished trial has the number)."""


def cell_summaries(
    config: GridConfig, outcomes: tuple[TrialOutcome, ...]
) -> list[dict[str, object]]:
    """Returns one row (`SUMMARY_COLUMNS`) per approach and fitness, in config order."""
    rows = []
    for approach in config.approaches:
        for fitness in config.fitnesses:
            cell = [
                o
                for o in outcomes
                if layout.parse_trial_key(o.trial_key)[:2] == (approach, fitness)
            ]
            done = [o for o in cell if o.status == "FINISHED"]
            row: dict[str, object] = {
                "approach": approach,
                "fitness": fitness,
                "finished": len(done),
                "trials": len(cell),
            }
            for name in ("best_loss", "coverage", "qd_score"):
                values = [getattr(o, name) for o in done if getattr(o, name) is not None]
                if name == "best_loss":
                    row["best_loss_min"] = min(values) if values else None
                row[f"{name}_median"] = statistics.median(values) if values else None
            rows.append(row)
    return rows


def log_grid_summary(
    store: RunStore, run_id: str, grid: Grid, outcomes: tuple[TrialOutcome, ...]
) -> None:
    """Logs the grid's summary to its parent run as one table (`layout.GRID_SUMMARY`) and
    as a Markdown table in its description, which the MLflow UI shows on the run's page
    (a resumed grid writes both again, updated)."""
    rows = cell_summaries(grid.config, outcomes)
    data = [[row[c] for c in SUMMARY_COLUMNS] for row in rows]
    store.log_document(
        run_id, {"columns": list(SUMMARY_COLUMNS), "data": data}, layout.GRID_SUMMARY
    )
    store.set_tag(run_id, layout.NOTE, f"{grid_description(grid)}\n\n{summary_markdown(rows)}")


def summary_markdown(rows: list[dict[str, object]]) -> str:
    """Returns the summary rows as a Markdown table."""

    def cell(value: object) -> str:
        if not isinstance(value, float):
            return "–" if value is None else str(value)
        return f"{value:.4g}" if abs(value) < 1e4 else f"{value:,.0f}"

    lines = [
        "| approach | fitness | finished | best loss min | median | coverage | QD-score |",
        "|---|---|---|---|---|---|---|",
    ]
    numbers = SUMMARY_COLUMNS[4:]
    for r in rows:
        values = " | ".join(cell(r[c]) for c in numbers)
        lines.append(
            f"| {r['approach']} | {r['fitness']} | {r['finished']}/{r['trials']} | {values} |"
        )
    return "\n".join(lines)


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
        "population, the best linkage). When the grid ends, the table below (and the "
        f"artefact `{layout.GRID_SUMMARY}`) summarises each approach and fitness over its "
        "finished trials.\n\n"
        f"Figures and statistics: `linkevo report {grid.grid_id}` (also logged here under "
        f"`report/`). A trial's linkage: `linkevo pull RUN_ID`, or `linkevo pull "
        f"{grid.grid_id} --best --fitness {cfg.fitnesses[0]}`. Resolved config: "
        "`grid_config.toml`."
    )
