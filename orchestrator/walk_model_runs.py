"""Provides the learned walk model's work for `linkevo walkmodel`: its training data read
from the store's walk maps, a fit measured on whole held-out repertoires, the model logged
as an MLflow run of its own kind (`walk_model`), and whole repertoires predicted and logged
beside their walk maps as `walkpred.parquet`.

Training data are the rows of walk maps (`linkevo walkmap`, or a walking trial's own):
`sim.robot.walk_features.walk_targets` of every walked cell.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.algorithms.walk_model import Prediction, WalkData, WalkModel
from linkevo.sim.robot.walk_features import (
    FEATURE_NAMES,
    FEATURES_VERSION,
    walk_features,
    walk_targets,
)
from linkevo.sim.robot.walk_rows import FLOOR_ORDER, Status
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.artifacts import write_parquet_atomic
from linkevo.workers.store.runs import NotFound, RunStore, TrialRun
from linkevo.workers.store.tables import bin_columns
from linkevo.workers.store.walk_models import WalkModelError


@dataclass(frozen=True)
class WalkedRepertoire:
    """One repertoire's walked cells: its trial, cells (N,) and their walks."""

    trial: TrialRun
    cells: np.ndarray
    data: WalkData


def walked_repertoires(store: RunStore, refs: list[str]) -> list[WalkedRepertoire]:
    """Returns the walked cells of every repertoire trial `refs` name (run ids or grid
    ids), with their features; a grid's trials without a walk map are passed over.

    Raises:
        NotFound: a REF names no repertoire trial, or a trial run without a walk map.
        WalkModelError: none of them has a walked cell.
    """
    out = []
    with tempfile.TemporaryDirectory(prefix="linkevo-walkmodel-") as tmp:
        for ref in refs:
            found = store.repertoires(ref)
            for trial in found.trials:
                walks = store.walk_map(trial.run_id, Path(tmp) / f"{trial.run_id}-walks")
                if walks is None:
                    if found.grid_id is None:
                        raise NotFound(
                            f"run {trial.run_id} ({trial.trial_key}) has no walk map to learn "
                            f"from; make one with: linkevo walkmap {trial.run_id}"
                        )
                    continue
                table = store.repertoire(trial.run_id, Path(tmp) / trial.run_id)
                table = table[
                    table["cell"].isin(walks.loc[walks["status"] == Status.WALKED, "cell"])
                ]
                if table.empty:
                    continue
                cells = table["cell"].to_numpy(dtype=np.int64)
                genomes = np.stack(table["genome"].to_numpy()).astype(np.float64)
                distance, breaks = walk_targets(walks, cells)
                features = walk_features(genomes, trial.mode)
                out.append(WalkedRepertoire(trial, cells, WalkData(features, distance, breaks)))
    if not out:
        raise WalkModelError(
            f"no walked cell in {', '.join(refs)}: make walk maps first (linkevo walkmap REF)"
        )
    return out


def split_by_repertoire(n: int, holdout: float, seed: int) -> tuple[list[int], list[int]]:
    """Returns (training, held-out) repertoire indices: `round(holdout * n)` of `n`
    repertoires, at least one, held out at random (seeded); none when holdout is 0.

    Raises:
        WalkModelError: a hold-out outside [0, 1), or one that leaves nothing to train on.
    """
    if not 0.0 <= holdout < 1.0:
        raise WalkModelError(f"--holdout {holdout:g}: allowed a share from 0 up to (not) 1")
    if holdout == 0.0:
        return list(range(n)), []
    count = max(1, round(holdout * n))
    if count >= n:
        raise WalkModelError(
            f"--holdout {holdout:g} of {n} walked repertoire(s) leaves none to train on: "
            "give more repertoires with walk maps, or --holdout 0"
        )
    order = np.random.default_rng(seed).permutation(n)
    return sorted(order[count:].tolist()), sorted(order[:count].tolist())


def pooled(repertoires: list[WalkedRepertoire]) -> WalkData:
    """Returns the walks of several repertoires as one data set."""
    parts = [r.data for r in repertoires]
    return WalkData(
        np.concatenate([p.features for p in parts]),
        np.concatenate([p.distance for p in parts]),
        np.concatenate([p.breaks for p in parts]),
    )


def figures(prediction: Prediction, data: WalkData) -> dict[str, float]:
    """Returns how well `prediction` matches walks `data`: per floor, the Spearman rank
    correlation of predicted and walked distance among the cells that walk there without
    breaking (`spearman_<floor>`) and the break classifier's ROC AUC (`break_auc_<floor>`);
    `break_auc` over both floors' walks; the counts behind them (`sound_<floor>`,
    `walked_<floor>`). NaN where a figure has too few walks to exist."""
    from scipy.stats import mannwhitneyu, spearmanr

    def auc(p: np.ndarray, broke: np.ndarray) -> float:
        if broke.all() or not broke.any():
            return math.nan
        u = mannwhitneyu(p[broke], p[~broke]).statistic
        return float(u / (broke.sum() * (~broke).sum()))

    out: dict[str, float] = {}
    for k, floor in enumerate(FLOOR_ORDER):
        sound = np.isfinite(data.distance[:, k])
        walked = np.isfinite(data.breaks[:, k])
        rho = (
            spearmanr(prediction.distance[sound, k], data.distance[sound, k]).statistic
            if sound.sum() > 2
            else math.nan
        )
        out[f"spearman_{floor}"] = float(rho)
        out[f"break_auc_{floor}"] = auc(prediction.p_break[walked, k], data.breaks[walked, k] > 0)
        out[f"sound_{floor}"] = float(sound.sum())
        out[f"walked_{floor}"] = float(walked.sum())
    walked = np.isfinite(data.breaks)
    out["break_auc"] = auc(prediction.p_break[walked], data.breaks[walked] > 0)
    return out


@dataclass(frozen=True)
class FittedModel:
    """A fitted walk model, what it learned from and (with a hold-out) how it does on the
    repertoires it never saw (`figures`; empty without a hold-out)."""

    model: WalkModel
    trained_on: list[TrialRun]
    held_out: list[TrialRun]
    walks: int
    figures: dict[str, float]
    prediction: Prediction | None
    truth: WalkData | None


def fit(repertoires: list[WalkedRepertoire], holdout: float, seed: int = 0) -> FittedModel:
    """Fits the model on the repertoires not held out and measures it on those held out.

    The model returned is the one measured: trained without the held-out repertoires, so
    its figures are its own (with --holdout 0 it learns from all, unmeasured).
    """
    train, test = split_by_repertoire(len(repertoires), holdout, seed)
    data = pooled([repertoires[i] for i in train])
    model = WalkModel(len(FEATURE_NAMES)).fit(data, seed=seed)
    prediction = truth = None
    found: dict[str, float] = {}
    if test:
        truth = pooled([repertoires[i] for i in test])
        prediction = model.predict(truth.features)
        found = figures(prediction, truth)
    return FittedModel(
        model=model,
        trained_on=[repertoires[i].trial for i in train],
        held_out=[repertoires[i].trial for i in test],
        walks=int(np.isfinite(data.breaks).sum()),
        figures=found,
        prediction=prediction,
        truth=truth,
    )


def log_model(store: RunStore, fitted: FittedModel, refs: list[str], seed: int) -> str:
    """Logs a fitted model as a run of kind `walk_model` and returns its run id: the weights
    (`walk_model.pt`, a torch state dict: `torch.load(path, weights_only=True)`), the
    description (`walk_model.json`: the features' definition, the repertoires trained on
    and held out, the figures) and, with a hold-out, the held-out walks predicted against
    walked (`walk_model.png`)."""
    import torch

    from linkevo.workers.store.tracking import ensure_experiment

    experiment_id = ensure_experiment(store.uri, store.experiment)
    description = {
        "features": {"version": FEATURES_VERSION, "names": list(FEATURE_NAMES)},
        "floors": list(FLOOR_ORDER),
        "target": "cm walked in 10 s (credited, sim.robot.walk_rows.credited_cm); breaks",
        "sources": refs,
        "trained_on": [t.run_id for t in fitted.trained_on],
        "held_out": [t.run_id for t in fitted.held_out],
        "walks": fitted.walks,
        "figures": {k: (None if math.isnan(v) else v) for k, v in fitted.figures.items()},
    }
    run_id = store.create_run(
        "walk-model",
        {layout.KIND: layout.WALK_MODEL, layout.FEATURES: FEATURES_VERSION},
        experiment_id=experiment_id,
    )
    params = {
        "sources": ",".join(refs)[:500],
        "seed": seed,
        "repertoires": len(fitted.trained_on),
        "held_out": len(fitted.held_out),
        "walks": fitted.walks,
    }
    store.log_params(run_id, params)
    for name, value in fitted.figures.items():
        if math.isfinite(value):
            store.log_metric(run_id, name, value)
    with tempfile.TemporaryDirectory(prefix="linkevo-walkmodel-") as tmp:
        weights = Path(tmp) / layout.WALK_MODEL_PT
        torch.save(fitted.model.state_dict(), weights)
        store.log_artefact(run_id, weights)
        store.log_document(run_id, description, layout.WALK_MODEL_JSON)
        if fitted.prediction is not None and fitted.truth is not None:
            from linkevo.workers.plots.walk_model_figure import draw_predicted_vs_walked

            png = draw_predicted_vs_walked(
                fitted.prediction, fitted.truth, fitted.figures, Path(tmp) / layout.WALK_MODEL_PNG
            )
            store.log_artefact(run_id, png)
    store.end_run(run_id)
    return run_id


def prediction_frame(model: WalkModel, table: pd.DataFrame, mode: str) -> pd.DataFrame:
    """Returns the predicted walks (`workers.store.tables.PREDICTION_COLUMNS` and the
    bins) of every cell of a repertoire table (a row per filled cell), per cell and floor."""
    genomes = np.stack(table["genome"].to_numpy()).astype(np.float64).reshape(-1, 56)
    prediction = model.predict(walk_features(genomes, mode))
    cells = table["cell"].to_numpy(dtype=np.int64)
    parts = []
    bins = bin_columns(table.columns)
    for k, floor in enumerate(FLOOR_ORDER):
        part = pd.DataFrame(
            {
                "cell": cells,
                "floor": floor,
                "predicted_cm": prediction.distance[:, k],
                "spread_cm": prediction.spread[:, k],
                "p_break": prediction.p_break[:, k],
            }
        )
        parts.append(pd.concat([part, table[bins].reset_index(drop=True)], axis=1))
    return pd.concat(parts, ignore_index=True)


def predict(store: RunStore, trial: TrialRun, model: WalkModel, model_run: str) -> pd.DataFrame:
    """Predicts every filled cell of a repertoire trial and logs `walkpred.parquet` (tagged
    with the model's run id) to its run; returns the rows."""
    with tempfile.TemporaryDirectory(prefix="linkevo-walkpred-") as tmp:
        table = store.repertoire(trial.run_id, Path(tmp) / "in")
        frame = prediction_frame(model, table, trial.mode)
        path = Path(tmp) / layout.WALK_PREDICTION
        write_parquet_atomic(path, {c: frame[c].to_numpy() for c in frame.columns})
        store.log_artefact(trial.run_id, path)
        store.set_tag(trial.run_id, layout.PREDICTED_BY, model_run)
    return frame


def describe(fitted: FittedModel) -> dict:
    """Returns `walkmodel fit --json`'s document: the figures and what they rest on."""
    return {
        **{k: (None if math.isnan(v) else round(v, 4)) for k, v in fitted.figures.items()},
        "trained_on": [t.trial_key for t in fitted.trained_on],
        "held_out": [t.trial_key for t in fitted.held_out],
        "walks": fitted.walks,
    }
