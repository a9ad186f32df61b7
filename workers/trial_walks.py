"""Provides what a trial walks, or writes of its walks, at its end: the re-ranking walks
of a path trial (`walk_rerank`), a walking trial's walk tables (`walks.parquet`, and for
a repertoire its walk map) and its best walker confirmed on the full model."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.sim import decode, simulate
from linkevo.sim.linkage.linkage_doc import to_document
from linkevo.sim.linkage.physical import physical_checks
from linkevo.sim.robot.hexapod import FLAT
from linkevo.sim.robot.walk_rows import COLUMNS, Status, credited_cm
from linkevo.workers.store.artifacts import write_json_atomic, write_parquet_atomic
from linkevo.workers.store.run_layout import (
    BEST_CONFIRMED,
    BEST_WALKER,
    WALK_LOG,
    WALK_MAP,
    WALK_MAP_PNG,
    WALK_RERANK,
)
from linkevo.workers.store.tables import bin_columns
from linkevo.workers.trial_spec import TrialSpec
from linkevo.workers.walk_log import WalkLog


def rerank_by_walking(spec: TrialSpec, view: dict[str, np.ndarray], out_dir: Path) -> float:
    """Walks the trial's `spec.walk_rerank` lowest-loss final linkages that pass the
    physical checks once each on the simulated robot (flat floor, the walk map's protocol,
    `sim.robot.walk_map`), writes `walk_rerank.parquet` (their rows, with loss) and the furthest
    walker that does not break as `best_walker.json`; returns its distance in cm (NaN when
    none walks).

    Args:
        view: the optimizer's final `view()`: genome (N, 56), loss (N,), cell (N,) where
            it has cells.
    """
    from linkevo.sim.robot.walk_map import CellBatch, walk_cells  # MuJoCo: only when asked

    genomes = np.asarray(view["genome"], dtype=np.float64)
    loss = np.asarray(view["loss"], dtype=np.float64)
    cells = np.asarray(view.get("cell", np.arange(len(loss))), dtype=np.int64)
    batch = decode(genomes, spec.mode)
    order = np.lexsort((cells, loss))
    keep = order[physical_checks(batch, simulate(batch, spec.n_angles)).buildable[order]]
    keep = keep[: spec.walk_rerank]
    walked = CellBatch(cells[keep], genomes[keep], spec.mode, (FLAT,))
    rows = walk_cells(walked, spec.robot())
    distance = np.array([r["mean_distance_cm"] for r in rows], dtype=float)
    sound = np.array([r["status"] == Status.WALKED and not r["breaks"] for r in rows], dtype=bool)
    columns = {c: np.array([r[c] for r in rows]) for c in COLUMNS}
    write_parquet_atomic(
        out_dir / WALK_RERANK, {**columns, "loss": loss[keep], "genome": genomes[keep]}
    )
    if not (sound & np.isfinite(distance)).any():
        return math.nan
    best = int(np.nanargmax(np.where(sound, distance, np.nan)))
    meta = {"cell": int(cells[keep][best]), "walk_cm": float(distance[best])}
    write_json_atomic(out_dir / BEST_WALKER, to_document(genomes[keep][best], spec.mode, meta=meta))
    return float(distance[best])


def write_walk_tables(log: WalkLog, view: dict[str, np.ndarray], spec: TrialSpec, out_dir: Path):
    """Writes a walking trial's walk log (`walks.parquet`: every candidate it built) and,
    for a repertoire, the walk map of its cells (`walkmap.parquet` and `walkmap.png`, as
    `linkevo walkmap` writes them: explorer, pull and report read them alike)."""
    from linkevo.workers.plots.walk_map_figure import draw_walk_map

    write_parquet_atomic(out_dir / WALK_LOG, log.table())
    bins = bin_columns(list(view))
    if not bins:
        return
    frame = log.walk_map(view["cell"], np.asarray(view["genome"], dtype=np.float64))
    cells = pd.DataFrame({"cell": view["cell"], **{b: view[b] for b in bins}})
    frame = frame.merge(cells, on="cell", how="left")
    write_parquet_atomic(out_dir / WALK_MAP, {c: frame[c].to_numpy() for c in frame.columns})
    title = f"{spec.approach} F_w, seed {spec.seed}"
    draw_walk_map(frame, spec.approach, title, out_dir / WALK_MAP_PNG)


def confirm_best_walker(
    spec: TrialSpec, log: WalkLog, genome: np.ndarray, loss: float, out_dir: Path
) -> dict[str, float]:
    """Walks a walking trial's best linkage again on the full model from hand-placed starts
    (`sim.robot.confirmation`), writes `best_confirmed.json` and returns its metrics: each floor's
    full-model mean credited distance (`best_full_<floor>_cm`), whether the two models agree
    (`best_models_agree`, 1 or 0), whether the full model's repeats disagree widely (`best_chaotic`)
    or owe most of their distance to sliding (`best_slides`), and the leg's width, stroke and crank
    share (`sim.robot.leg.Leg.shape`). A best that does not walk soundly on both floors (its loss in
    the broken tiers) has nothing to confirm: {}."""
    from linkevo.sim.robot.confirmation import confirm_walk  # MuJoCo: only when asked
    from linkevo.sim.robot.leg import leg_from_genome
    from linkevo.sim.robot.walk_fitness import SOUND_BELOW

    if not loss < SOUND_BELOW:
        return {}
    at = [i for i in range(len(log)) if np.array_equal(log.genome[i], genome)]
    rows = log.rows(at[-1]) if at else {}
    lean = {
        floor: credited_cm(row) if row["status"] == Status.WALKED and not row["breaks"] else None
        for floor, row in rows.items()
    }
    confirmed = confirm_walk(leg_from_genome(genome, spec.mode), lean, spec.robot())
    write_json_atomic(out_dir / BEST_CONFIRMED, {"genome": genome.tolist(), **confirmed.as_dict()})
    metrics = {f"best_full_{f.floor}_cm": f.full_mean_cm for f in confirmed.floors}
    return metrics | {
        "best_models_agree": float(confirmed.agrees),
        "best_chaotic": float(confirmed.chaotic),
        "best_slides": float(confirmed.slides),
        "best_leg_width_cm": confirmed.shape["size_cm"][0],
        "best_stroke_cm": confirmed.shape["stroke_cm"],
        "best_crank_share": confirmed.shape["crank_share"],
    }
