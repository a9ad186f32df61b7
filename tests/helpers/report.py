"""Writes a real MLflow store holding a grid in the layout the grid driver records.

The store is a real sqlite database with file artefacts, written through `MlflowClient`
exactly as the driver does (parent run + nested trial runs, batched metrics, parquet and
CSV artefacts). The numbers are drawn with numpy so each test knows what to expect: with
Fp the MAP-Elites approaches have lower losses than NSGA-II, and NSGA-II lower than EA;
with Fsl every approach draws its losses from one distribution, and paths are larger.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from mlflow.entities import Metric, Param, RunTag
from mlflow.tracking import MlflowClient

from linkevo.sim.linkage.descriptors import DESCRIPTOR_SPACES, cell_index
from linkevo.sim.linkage.linkage_doc import to_document
from linkevo.sim.study import STUDY_EVALUATIONS

N_GENES = 56
N_ANGLES = 40
FP_LEVEL = {"EA": 12.0, "NSGA2": 7.0}
"""Median final best loss with Fp per approach; MAP-Elites approaches use MAP_FP_LEVEL."""
MAP_FP_LEVEL = 5.0
FSL_LEVEL = -20.0
PATH_SIZE = {"Fp": 8.0, "Fsl": 20.0}


@dataclass(frozen=True)
class GridSpec:
    """What to write.

    Attributes:
        grid_id: the grid id tag.
        approaches: approach names (as the grid config spells them).
        fitnesses: fitness names.
        trials: trials per (approach, fitness).
        iterations: logged iterations per trial.
        batch_size: evaluations per iteration.
        archive_rows: rows of each final repertoire / population parquet.
        failed: trial keys recorded as FAILED (partial metrics, no artefacts).
        missing: trial keys never started (no run at all).
        seed: numpy seed of the drawn numbers.
        budget: the config's evaluations per trial (the study's by default, so that the
            report judges the claims; below it the report is a pipeline check).
    """

    grid_id: str = "g0test"
    approaches: tuple[str, ...] = ("EA", "NSGA2", "MAP-WH", "MAP-ST")
    fitnesses: tuple[str, ...] = ("Fp", "Fsl")
    trials: int = 4
    iterations: int = 6
    batch_size: int = 50
    archive_rows: int = 60
    failed: tuple[str, ...] = ()
    missing: tuple[str, ...] = ()
    seed: int = 0
    experiment: str = "linkevo"
    budget: int = STUDY_EVALUATIONS
    extra_params: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class WrittenGrid:
    """What was written: ids, and per trial key the run id and drawn final best loss."""

    uri: str
    parent_run_id: str
    run_ids: dict[str, str]
    final_best: dict[str, float]


def store_uri(folder: Path) -> str:
    """Returns the sqlite URI of a store in `folder` (artefacts in folder/mlartifacts)."""
    return f"sqlite:///{(folder / 'mlflow.db').resolve()}"


def _experiment(client: MlflowClient, folder: Path, name: str, served: bool) -> str:
    existing = client.get_experiment_by_name(name)
    if existing is not None:
        return existing.experiment_id
    if served:  # the server's default root: proxied mlflow-artifacts:/ URIs
        return client.create_experiment(name)
    return client.create_experiment(name, artifact_location=(folder / "mlartifacts").as_uri())


def _history(rng, approach: str, final: float, spec: GridSpec) -> pd.DataFrame:
    """Returns a trial's metrics.csv table: best loss falling to `final`."""
    k = np.arange(spec.iterations)
    drops = rng.exponential(0.5, spec.iterations)
    best = final + np.append(np.cumsum(drops[::-1])[::-1][1:], 0.0)
    table = pd.DataFrame(
        {
            "iteration": k,
            "evaluations": (k + 1) * spec.batch_size,
            "best_loss": best,
            "mean_loss": best + rng.uniform(1.0, 2.0, spec.iterations),
        }
    )
    coverage = np.linspace(0.05, 0.5, spec.iterations) * rng.uniform(0.8, 1.2)
    table["coverage"] = coverage
    table["qd_score"] = coverage * 10_000 * (100 - best)
    common = np.linspace(0.1, 0.6, spec.iterations) * rng.uniform(0.8, 1.2)
    table["common_coverage"] = common
    table["common_qd_score"] = common * 10_000 * (100 - best)
    table["path_diversity"] = np.where(k == k[-1], rng.uniform(0.2, 1.0), np.nan)
    if approach == "NSGA2":
        table["hypervolume"] = np.linspace(1.0, 2.0, spec.iterations)
    return table


def _paths(rng, n: int, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Returns (foot_x, foot_y), each (n, 40): ellipses around `size`, a few NaN angles."""
    theta = np.linspace(0, 2 * np.pi, N_ANGLES, endpoint=False)
    width = size * rng.uniform(0.6, 1.4, (n, 1))
    height = width * rng.uniform(0.2, 0.6, (n, 1))
    x = width / 2 * np.cos(theta) + rng.normal(0, 0.05, (n, N_ANGLES))
    y = height / 2 * np.sin(theta)
    broken = rng.random((n, N_ANGLES)) < 0.05
    return np.where(broken, np.nan, x), np.where(broken, np.nan, y)


def _list_column(values: np.ndarray) -> pa.Array:
    """Returns a list<double> column from a (n, k) array."""
    n, k = values.shape
    offsets = pa.array(np.arange(0, (n + 1) * k, k, dtype=np.int32))
    return pa.ListArray.from_arrays(offsets, pa.array(values.ravel()))


def _archive(rng, approach: str, fitness: str, final: float, spec: GridSpec) -> pa.Table:
    """Returns the final repertoire (MAP-*) or population table; its best loss is `final`."""
    n = spec.archive_rows
    loss = final + np.concatenate([[0.0], rng.exponential(2.0, n - 1)])
    foot_x, foot_y = _paths(rng, n, PATH_SIZE[fitness])
    columns: dict[str, pa.Array] = {}
    space = DESCRIPTOR_SPACES.get(approach)
    if space is not None:
        flat = rng.choice(space.n_cells, n, replace=False)
        bins = np.stack(np.unravel_index(flat, space.shape), axis=1)
        columns["cell"] = pa.array(cell_index(bins, space))
    else:
        columns["cell"] = pa.array(np.full(n, -1, dtype=np.int64))
    columns["loss"] = pa.array(loss)
    if approach == "NSGA2":
        share = rng.uniform(0.2, 0.8, n)
        columns["loss_0"] = pa.array(loss * share)
        columns["loss_1"] = pa.array(loss * (1 - share) + 0.1 * rng.random(n))
    columns["error"] = pa.array(np.zeros(n, dtype=np.int64))
    columns["angle_error"] = pa.array(np.zeros(n))
    if space is not None:
        values = bins + rng.random(bins.shape)
        for d in range(space.dims):
            columns[f"desc_{d}"] = pa.array(values[:, d] * space.step[d])
        for d in range(space.dims):
            columns[f"bin_{d}"] = pa.array(bins[:, d].astype(np.int64))
    columns["genome"] = _list_column(rng.random((n, N_GENES)))
    columns["sigma"] = pa.array(np.full(n, 0.1))
    columns["foot_x"] = _list_column(foot_x)
    columns["foot_y"] = _list_column(foot_y)
    return pa.table(columns)


def _final_best(rng, approach: str, fitness: str) -> float:
    if fitness == "Fsl":
        return FSL_LEVEL + rng.normal(0, 1.0)
    level = MAP_FP_LEVEL if approach.startswith("MAP-") else FP_LEVEL[approach]
    return level + rng.normal(0, 0.3)


def _log_metrics(client: MlflowClient, run_id: str, table: pd.DataFrame) -> None:
    metrics = [
        Metric(name, float(value), 0, int(step))
        for name in table.columns
        if name != "iteration"
        for step, value in zip(table.iteration, table[name], strict=True)
    ]
    for start in range(0, len(metrics), 1000):
        client.log_batch(run_id, metrics=metrics[start : start + 1000])


def write_grid(folder: Path, spec: GridSpec, server_uri: str | None = None) -> WrittenGrid:
    """Writes `spec`'s grid and returns its ids.

    The store is the sqlite one in `folder`, or the tracking server at `server_uri`
    (artefacts then go through the server); `folder` holds the files before logging.
    """
    folder.mkdir(parents=True, exist_ok=True)
    uri = server_uri or store_uri(folder)
    client = MlflowClient(tracking_uri=uri)
    experiment = _experiment(client, folder, spec.experiment, served=server_uri is not None)
    config = {
        "trials": spec.trials,
        "approaches": list(spec.approaches),
        "fitnesses": list(spec.fitnesses),
        "evaluations": spec.budget,
        "batch_size": spec.batch_size,
        "mode": "paper",
        "seed": spec.seed,
    }
    parent = client.create_run(
        experiment,
        run_name=f"grid-{spec.grid_id}",
        tags={
            "linkevo.kind": "grid",
            "grid_id": spec.grid_id,
            "code_version": "test",
            "host": "localhost",
        },
    )
    parent_id = parent.info.run_id
    params = {k: json.dumps(v) if isinstance(v, list) else str(v) for k, v in config.items()}
    params.update(spec.extra_params)
    client.log_batch(parent_id, params=[Param(k, v) for k, v in params.items()])
    work = folder / "work"
    work.mkdir(exist_ok=True)
    config_path = work / "grid_config.json"
    config_path.write_text(json.dumps(config))
    client.log_artifact(parent_id, str(config_path))
    rng = np.random.default_rng(spec.seed)
    run_ids, finals = {}, {}
    for approach in spec.approaches:
        for fitness in spec.fitnesses:
            for index in range(spec.trials):
                key = f"{approach}/{fitness}/{index:02d}"
                if key in spec.missing:
                    continue
                final = _final_best(rng, approach, fitness)
                run = client.create_run(
                    experiment,
                    run_name=key,
                    tags={
                        "mlflow.parentRunId": parent_id,
                        "linkevo.kind": "trial",
                        "grid_id": spec.grid_id,
                        "trial_key": key,
                        "approach": approach,
                        "fitness": fitness,
                        "seed": str(1000 + index),
                        "trial_index": str(index),
                    },
                )
                run_id = run.info.run_id
                run_ids[key] = run_id
                client.log_batch(
                    run_id,
                    params=[
                        Param("approach", approach),
                        Param("fitness", fitness),
                        Param("mode", "paper"),
                        Param("evaluations", str(config["evaluations"])),
                        Param("batch_size", str(spec.batch_size)),
                        Param("seed", str(1000 + index)),
                        Param("n_angles", str(N_ANGLES)),
                        Param("target", "D16"),
                    ],
                )
                history = _history(rng, approach, final, spec)
                if key in spec.failed:
                    _log_metrics(client, run_id, history.iloc[: spec.iterations // 2])
                    client.log_batch(run_id, tags=[RunTag("error", "RuntimeError: boom")])
                    client.set_terminated(run_id, "FAILED")
                    continue
                finals[key] = float(history.best_loss.min())
                _log_metrics(client, run_id, history)
                trial_dir = work / key.replace("/", "_")
                trial_dir.mkdir()
                history.to_csv(trial_dir / "metrics.csv", index=False)
                name = "repertoire" if approach.startswith("MAP-") else "population"
                archive = _archive(rng, approach, fitness, final, spec)
                pq.write_table(archive, trial_dir / f"{name}.parquet")
                best = int(np.argmin(archive.column("loss").to_numpy()))
                path = {
                    axis: [
                        None if np.isnan(v) else v
                        for v in archive.column(f"foot_{axis}")[best].as_py()
                    ]
                    for axis in ("x", "y")
                }
                # A real document of the best genome, carrying the drawn foot path (the
                # report's path-size finding reads it; the physical checks read the genome).
                genome = np.array(archive.column("genome")[best].as_py())
                document = {**to_document(genome), "foot_path": path}
                (trial_dir / "best_linkage.json").write_text(json.dumps(document))
                (trial_dir / "settings.json").write_text(json.dumps({"approach": approach}))
                for path in sorted(trial_dir.iterdir()):
                    client.log_artifact(run_id, str(path))
                client.set_terminated(run_id, "FINISHED")
    client.set_terminated(parent_id, "FINISHED")
    return WrittenGrid(uri=uri, parent_run_id=parent_id, run_ids=run_ids, final_best=finals)
