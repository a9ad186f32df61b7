"""Provides the one trial loop (ask -> evaluate -> tell -> record) and its spec and result."""

from __future__ import annotations

import importlib.metadata
import json
import math
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from linkevo.algorithms import Optimizer
from linkevo.sim.linkage.linkage_doc import to_document
from linkevo.sim.linkage.path_diversity import path_diversity
from linkevo.sim.study import (
    REPERTOIRE_APPROACHES,
)
from linkevo.workers.checkpoint import (
    CHECKPOINT_FILE,
    Checkpoint,
    CheckpointError,
    load_checkpoint,
    save_checkpoint,
)
from linkevo.workers.evaluators import Evaluator
from linkevo.workers.plots.linkage import draw_linkage
from linkevo.workers.plots.repertoire import draw_trial_maps
from linkevo.workers.recorders import MetricsCsv, Recorder
from linkevo.workers.seed_repertoire import Seed
from linkevo.workers.store.artifacts import atomic_path, write_json_atomic, write_parquet_atomic
from linkevo.workers.store.run_layout import (
    BEST_JSON,
    BEST_PNG,
    CHECKPOINT_DIR,
    ENCODER_PT,
    METRICS_FILE,
    PREDICTION_MAP,
    RESULT_FILE,
    SETTINGS_FILE,
)
from linkevo.workers.trial_spec import TrialSpec, build_optimizer, resolve_target
from linkevo.workers.trial_walks import confirm_best_walker, rerank_by_walking, write_walk_tables

FLOAT32_COLUMNS: tuple[str, ...] = ("foot_x", "foot_y")
"""Repertoire columns stored as float32: the foot paths, for drawing and inspection, are
most of a repertoire's bytes, and 7 digits are far finer than a LEGO build. Everything
else keeps float64: the genome rebuilds the linkage bit for bit (its genes are cut at
exact bin edges), losses and descriptors are what statistics and cells are computed
from, and all are small."""


@dataclass(frozen=True)
class TrialResult:
    """How a trial ended.

    Attributes:
        spec: the trial.
        out_dir: where its files are.
        iterations: completed iterations (the initial population is the first).
        evaluations: evaluations done.
        best_loss: the lowest single-objective loss kept at the end.
        metrics: the last iteration's metrics.
        seconds: wall time of this call (a resumed trial counts only its own part).
        timings: seconds spent per phase in this call: ask (parent selection and
            mutation), evaluate, tell (survivor selection / archive insertion), record
            (metrics, files, recorder), checkpoint, final (end-of-trial artefacts).
        stopped_by: "budget" or "max_seconds".
    """

    spec: TrialSpec
    out_dir: Path
    iterations: int
    evaluations: int
    best_loss: float
    metrics: dict[str, float]
    seconds: float
    timings: dict[str, float] = field(default_factory=dict)
    stopped_by: str = "budget"


def versions() -> dict[str, str]:
    """Returns the versions that shape a trial's numbers."""
    found = {"python": platform.python_version()}
    for package in ("linkevo", "numpy", "numba", "scipy"):
        try:
            found[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            found[package] = "unknown"
    return found


def _spec_doc(spec: TrialSpec) -> dict[str, object]:
    return json.loads(json.dumps(spec.to_dict()))


def _resume(
    spec: TrialSpec,
    optimizer: Optimizer,
    evaluator: Evaluator,
    log: MetricsCsv,
    recorder: Recorder,
    folder: Path,
) -> bool:
    checkpoint = load_checkpoint(folder)
    if checkpoint is None:
        return False
    saved = dict(checkpoint.spec)
    mine = _spec_doc(spec)
    # The budget and wall-clock limit may grow on resume; everything else must match.
    for key in ("evaluations", "walks", "max_seconds", "checkpoint_every"):
        saved.pop(key, None)
        mine.pop(key, None)
    path = folder / CHECKPOINT_FILE
    if saved != mine:
        diff = sorted(k for k in set(saved) | set(mine) if saved.get(k) != mine.get(k))
        raise CheckpointError(
            path,
            "it belongs to another trial; differing: "
            + ", ".join(f"{k} (saved {saved.get(k)!r}, now {mine.get(k)!r})" for k in diff),
        )
    try:
        optimizer.load_state_dict(checkpoint.state)
        evaluator.load_state_dict(checkpoint.state)
    except (KeyError, ValueError, TypeError, IndexError, AttributeError, RuntimeError) as exc:
        problem = f"missing entry {exc}" if isinstance(exc, KeyError) else str(exc)
        raise CheckpointError(path, f"its search state does not load: {problem}") from exc
    for row in log.truncate(checkpoint.rows):
        recorder.log_iteration(int(row["iteration"]), row)
    return True


def _checkpoint(
    spec: TrialSpec, state: dict[str, np.ndarray], optimizer: Optimizer, rows: int, folder: Path
) -> None:
    """Saves `state` (the optimizer's and the evaluator's, taken after a tell) with the
    metrics rows so far, and the encoder."""
    save_checkpoint(folder, Checkpoint(state, rows, _spec_doc(spec)))
    _write_torch_state(optimizer, folder / ENCODER_PT)


def _write_torch_state(optimizer: Optimizer, path: Path) -> None:
    """Saves an optimizer's torch state dict (MAP-AU's encoder), if it has one.

    The npz checkpoint already holds the same weights for resuming; this file is the
    encoder in torch's own format, loadable with `torch.load(path, weights_only=True)`.
    """
    torch_state = getattr(optimizer, "torch_state", None)
    if torch_state is None:
        return
    import torch

    with atomic_path(path) as tmp:
        torch.save(torch_state(), tmp)


def _write_final(spec: TrialSpec, optimizer: Optimizer, out_dir: Path) -> tuple[float, dict]:
    """Writes the end-of-trial files; returns the best loss and the kept view."""
    kept = "repertoire" if spec.approach in REPERTOIRE_APPROACHES else "population"
    view = optimizer.view()
    write_parquet_atomic(out_dir / f"{kept}.parquet", view, float32=FLOAT32_COLUMNS)
    draw_trial_maps(view, spec.approach, out_dir / f"{kept}.png")
    genome, loss = optimizer.best()
    write_json_atomic(out_dir / BEST_JSON, to_document(genome, spec.mode))
    draw_linkage(genome, spec.mode, out_dir / BEST_PNG)
    _write_torch_state(optimizer, out_dir / ENCODER_PT)
    return loss, view


def run_trial(
    spec: TrialSpec,
    evaluator: Evaluator,
    recorder: Recorder,
    out_dir: Path,
    resume: bool = False,
    seed: Seed | None = None,
) -> TrialResult:
    """Runs one trial: ask -> evaluate -> tell -> record, until the budget is spent.

    Writes into `out_dir`: `settings.json` (at the start), `metrics.csv` (one flushed row
    per iteration), `checkpoint/state.npz` (every `checkpoint_every` iterations and at
    the end, atomically), then `repertoire.parquet` and `repertoire.png` (MAP-*,
    RANDOM) or `population.parquet` and `population.png`
    (EA, NSGA2), `best_linkage.json`, `best_linkage.png`, `encoder.pt` (MAP-AU) and
    `result.json`; the final metric `path_diversity` (`sim.linkage.path_diversity`) goes to the
    recorder with the last iteration's step; finally it calls
    `recorder.log_artifacts(out_dir)`.

    With `resume`, the checkpoint (if any) is loaded, metrics.csv is cut back to the rows
    it had then, those rows are replayed to `recorder.log_iteration`, and the loop goes on;
    the metrics equal those of an uninterrupted run. Without it (or with no checkpoint) the
    trial starts afresh, replacing earlier files.

    Args:
        spec: the trial.
        evaluator: `evaluator(genomes (B, 56)) -> Evaluation` with fitness
            `spec.eval_fitness`, mode `spec.mode`, target `spec.target`, `spec.n_angles`.
        recorder: receives every iteration's metrics and the final files.
        out_dir: the trial's folder (created if missing).
        resume: continue from `out_dir/checkpoint` when it exists.
        seed: a walking trial's warm start (`spec.seed_from`'s repertoire and walk map,
            `workers.seed_repertoire`): its first batch, when the trial starts afresh.
    """
    start = time.monotonic()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    optimizer = build_optimizer(spec)
    optimizer.propose_with(evaluator.proposals(optimizer))
    log = MetricsCsv(out_dir / METRICS_FILE)
    folder = out_dir / CHECKPOINT_DIR
    if not (resume and _resume(spec, optimizer, evaluator, log, recorder, folder)):
        log.reset()
        (folder / CHECKPOINT_FILE).unlink(missing_ok=True)  # nothing else it did not write
        if seed is not None:
            optimizer.seed_with(seed.genomes)  # type: ignore[attr-defined]
            evaluator.seed_with(seed)  # type: ignore[attr-defined]
    write_json_atomic(
        out_dir / SETTINGS_FILE,
        {
            "spec": _spec_doc(spec),
            "optimizer": optimizer.settings(),
            "target": resolve_target(spec.target).to_dict(),
            "iterations": spec.iterations,
            "versions": versions(),
        },
    )
    laps = _Laps()
    stopped_by = _search(spec, optimizer, evaluator, recorder, log, folder, laps, start)
    best_loss, metrics = _finish(spec, optimizer, evaluator, recorder, out_dir)
    result = TrialResult(
        spec=spec,
        out_dir=out_dir,
        iterations=optimizer.iteration,
        evaluations=optimizer.evaluations,
        best_loss=best_loss,
        metrics=metrics,
        seconds=time.monotonic() - start,
        timings=laps.timings,
        stopped_by=stopped_by,
    )
    write_json_atomic(
        out_dir / RESULT_FILE,
        {
            "iterations": result.iterations,
            "evaluations": result.evaluations,
            "best_loss": result.best_loss,
            "metrics": metrics,
            "stopped_by": stopped_by,
            "seconds": result.seconds,
        },
    )
    laps.lap("final")
    recorder.log_artifacts(out_dir)
    return result


class _Laps:
    """Seconds spent per phase of a trial: ask, evaluate, tell, record, checkpoint, final."""

    def __init__(self) -> None:
        self.timings = dict.fromkeys(
            ("ask", "evaluate", "tell", "record", "checkpoint", "final"), 0.0
        )
        self._clock = time.perf_counter()

    def lap(self, phase: str) -> None:
        now = time.perf_counter()
        self.timings[phase] += now - self._clock
        self._clock = now


def _search(
    spec: TrialSpec,
    optimizer: Optimizer,
    evaluator: Evaluator,
    recorder: Recorder,
    log: MetricsCsv,
    folder: Path,
    laps: _Laps,
    start: float,
) -> str:
    """Runs ask -> evaluate -> tell -> record until the budget is spent (or the time
    limit); returns what stopped it ("budget" or "max_seconds").

    An iteration's bookkeeping runs while the next batch is being evaluated: a remote
    evaluator computes meanwhile (docs/grid.md, "Bookkeeping overlap"). ask() leaves what
    metrics() reads unchanged; the evaluator's metrics and the checkpoint state are taken
    right after tell(). A walking trial's budget is its walks (`TrialSpec.walks`), with
    `evaluations` a guard.
    """

    def bookkeeping(
        iteration: int, state: dict[str, np.ndarray] | None, own: dict[str, float]
    ) -> None:
        """Records iteration's metrics (the optimizer's, then the evaluator's `own`) and
        saves the checkpoint state taken after its tell."""
        metrics = optimizer.metrics() | own
        log.append(metrics)
        recorder.log_iteration(iteration, metrics)
        laps.lap("record")
        if state is not None:
            _checkpoint(spec, state, optimizer, iteration, folder)
            laps.lap("checkpoint")

    def budget_left() -> bool:
        if optimizer.evaluations + spec.batch_size > spec.evaluations:
            return False
        return not spec.walking_trial or evaluator.metrics()["walks"] < spec.walks

    deferred: tuple[int, dict[str, np.ndarray] | None, dict[str, float]] | None = None
    try:
        while budget_left():
            genomes = optimizer.ask()
            laps.lap("ask")
            pending = evaluator.submit(genomes, bar=optimizer.bar)
            laps.lap("evaluate")
            if deferred is not None:
                done, deferred = deferred, None
                bookkeeping(*done)
            evaluation = pending()
            laps.lap("evaluate")
            optimizer.tell(genomes, evaluation)
            laps.lap("tell")
            due = optimizer.iteration % spec.checkpoint_every == 0
            state = optimizer.state_dict() | evaluator.state_dict() if due else None
            deferred = (optimizer.iteration, state, evaluator.metrics())
            if spec.max_seconds is not None and time.monotonic() - start >= spec.max_seconds:
                return "max_seconds"
        return "budget"
    finally:  # a failed evaluation still leaves the last told iteration recorded
        if deferred is not None:
            bookkeeping(*deferred)


def _finish(
    spec: TrialSpec, optimizer: Optimizer, evaluator: Evaluator, recorder: Recorder, out_dir: Path
) -> tuple[float, dict]:
    """Writes the end-of-trial files, records the final measures (path diversity; the best
    walker with `walk_rerank`); returns the best loss kept and the last metrics."""
    folder = out_dir / CHECKPOINT_DIR
    state = optimizer.state_dict() | evaluator.state_dict()
    _checkpoint(spec, state, optimizer, optimizer.iteration, folder)
    best_loss, view = _write_final(spec, optimizer, out_dir)
    metrics = optimizer.metrics() | evaluator.metrics()
    if spec.walking_trial:
        log = evaluator.log  # type: ignore[attr-defined]
        write_walk_tables(log, view, spec, out_dir)
        if spec.surrogate == "sail":
            prediction = evaluator.prediction_map(optimizer)  # type: ignore[attr-defined]
            if prediction:  # no model, or it predicts no buildable leg: no map to draw
                write_parquet_atomic(out_dir / PREDICTION_MAP, prediction)
        confirmed = confirm_best_walker(spec, log, *optimizer.best(), out_dir)
        if confirmed:
            recorder.log_iteration(optimizer.iteration, confirmed)
        metrics |= confirmed
    metrics["path_diversity"] = (
        path_diversity(view["foot_x"], view["foot_y"], view["loss"]) if view else math.nan
    )
    recorder.log_iteration(optimizer.iteration, {"path_diversity": metrics["path_diversity"]})
    if spec.walk_rerank:
        walked = rerank_by_walking(spec, view, out_dir)
        metrics["best_walk_cm"] = walked
        recorder.log_iteration(optimizer.iteration, {"best_walk_cm": walked})
    return best_loss, metrics
