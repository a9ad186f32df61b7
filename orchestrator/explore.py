"""Provides `explore`: one self-contained, offline HTML page to browse repertoires and pick
a design (`linkevo explore RUN_ID|GRID_ID`).

The page shows a repertoire as a heatmap of loss (4-D maps folded into 2-D tiles, the
folding chosen on the page), each cell's linkage with its animated foot path, loss,
descriptors and physical checks (`sim.linkage.physical`), filters on the checks, a build sheet and
the `linkevo pull RUN_ID:CELL` command for a clicked cell, and two pinned cells side by
side. Where the trial has a walk map (`linkevo walkmap`), the map can be coloured by the
distance the simulated robot walks on a floor, filtered on "walks at least" and "does not
break", and a cell's panel shows its walks. Where the trial has predicted walks (`linkevo
walkmodel predict`), cells without a walk are coloured by the learned walk model's
prediction, marked as predicted on the map, in the legend, the panels and the pins; a SAIL
trial (`workers.walk_sail`) shows its walked map with its prediction map's other cells,
predicted by the trial's own model, marked alike. A grid's page holds every repertoire
trial behind a trial picker.

Each trial's cells travel as gzip-compressed JSON (base64) in the page, inflated by the
browser's own `DecompressionStream` when the trial is shown, so the page needs no network
and no library. A cell takes about 250 bytes: 2.1 MB for a study-budget repertoire of
8,400 cells.
"""

from __future__ import annotations

import base64
import gzip
import html
import json
import shutil
import tempfile
from collections.abc import Callable
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.orchestrator.pull import SAIL_MODEL, own_modules
from linkevo.sim import decode, simulate
from linkevo.sim.linkage.decoding import BEAM_KINDS, NODE_KINDS, LinkageBatch
from linkevo.sim.linkage.kinematics import Motion, take_rows
from linkevo.sim.linkage.linkage_doc import DEFAULT_UNIT_MM, json_floats
from linkevo.sim.linkage.physical import BUILDABLE_STRETCH, TOGGLE_DEG, physical_checks
from linkevo.sim.robot.hexapod import in_floor_order
from linkevo.sim.robot.walk_rows import SLIDING_SHARE, Status, beyond_bound_share, slide_share
from linkevo.sim.study import DEFAULT_ANGLES, FITNESSES, ordered
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.artifacts import write_bytes_atomic
from linkevo.workers.store.runs import RunStore, TrialRun
from linkevo.workers.store.tables import bin_columns, prediction_rows, space_of

GRID_DRAWN = 500
"""Cells per trial whose linkage a grid page draws by default (the lowest-loss ones)."""
PARTS_CELLS = 200
"""Cells per trial whose real Technic parts a page names (the lowest-loss ones that pass the
2-D checks; `real_parts`): about 30 ms a cell."""
TEMPLATE = "explorer_page.html"


def repertoire_view(
    table: pd.DataFrame,
    trial: TrialRun,
    drawn: int | None = None,
    walks: pd.DataFrame | None = None,
    predicted: pd.DataFrame | None = None,
    model_run: str | None = None,
) -> dict:
    """Returns the page's data of one repertoire.

    Args:
        table: the repertoire (`repertoire.parquet`): a row per filled cell with cell,
            loss, error, desc_<d>, bin_<d> and genome (56,).
        trial: the run it came from.
        drawn: draw the linkage of only the `drawn` lowest-loss cells (None: every cell).
        walks: the trial's walk map (`walkmap.parquet`), or None.
        predicted: the trial's predicted walks (`walkpred.parquet`), or None; model_run:
            the walk model's run that predicted them.

    Returns:
        A JSON-able dict: the trial's identity, the descriptor names and bins per
        descriptor, and `cells`, one per row in ascending loss: c (flat cell), b (bins, D),
        l (loss), d (descriptors, D), e (failed angles), k (checks: turns fully, buildable,
        smallest transmission angle in degrees, toggle passages, largest stretch, width and
        height in modules), g (the drawing, or None): n (nodes at the first assembled
        angle, (12, 2)), t (node kinds, (12,)), m (beams: start, end, kind, length, modules
        rounded on their own), f (foot path x and y, (2, A), None at failed angles), and
        with a walk map w: per floor of `floors`, [distance cm, breaks 0/1, reason, beyond
        the level-body no-slip bound 0/1, slides 0/1 (`sim.robot.walk_rows.SLIDING_SHARE`)]
        or None where the cell was not walked on it;
        with predicted walks p: per floor, [predicted cm, spread cm, probability of
        breaking] or None; q 1 where the loss itself is predicted (a SAIL trial's
        prediction-map cell, never walked); for the `PARTS_CELLS` lowest-loss cells that
        pass the 2-D checks, r (`real_parts`): the parts of one leg, or why real parts
        cannot build it. Positions are rounded
        to 0.1 module, lengths to 0.01, descriptors to 0.001, distances to 0.1 cm.
    """
    table = table.sort_values(["loss", "cell"], kind="stable").reset_index(drop=True)
    bins_of = bin_columns(table.columns)
    desc_columns = [f"desc_{c.removeprefix('bin_')}" for c in bins_of]
    space = space_of(trial.approach, len(bins_of))
    names = list(space.names)
    resolution = max(space.resolution, int(table[bins_of].to_numpy().max()) + 1)
    genomes = np.stack(table["genome"].to_numpy()).astype(np.float64)
    batch = decode(genomes, trial.mode)
    motion = simulate(batch, trial.n_angles)
    checks = physical_checks(batch, motion)
    first = np.argmax(motion.valid, axis=1)  # the first assembled angle (0 if none)
    nodes = motion.positions[np.arange(len(table)), :, first]  # (N, 12, 2)
    foot = motion.positions[np.arange(len(table)), motion.foot]  # (N, A, 2)
    k = [
        checks.turns_fully.astype(int).tolist(),
        checks.buildable.astype(int).tolist(),
        json_floats(checks.min_transmission_deg, 1),
        checks.toggle_passages.tolist(),
        json_floats(checks.max_stretch, 3),
        json_floats(checks.size_modules[:, 0], 1),
        json_floats(checks.size_modules[:, 1], 1),
    ]
    bins = table[bins_of].to_numpy().astype(int).tolist()
    descriptors = json_floats(table.reindex(columns=desc_columns).to_numpy(dtype=float), 3)
    loss = json_floats(table["loss"].to_numpy(), 4)
    error = (~motion.valid).sum(axis=1).astype(int).tolist()  # failed crank angles
    floors, walked = _walked(walks)
    parts = real_parts(batch, motion, np.flatnonzero(checks.buildable)[:PARTS_CELLS])
    guessed = _predicted(predicted)
    predicted_loss = table.get("predicted_loss", pd.Series(False, index=table.index)).to_numpy()
    if guessed:
        floors = in_floor_order({*floors, *(floor for _, floor in guessed)})
    cells = []
    for i, cell in enumerate(table["cell"].to_numpy().astype(int).tolist()):
        drawing = None
        if drawn is None or i < drawn:
            n_beams = int(batch.n_beams[i])
            lengths = batch.beam_length[i, :n_beams]
            drawing = {
                "n": json_floats(nodes[i], 1),
                "t": batch.node_kind[i].tolist(),
                "m": [
                    [int(s), int(e), int(kind), round(float(length), 2), modules]
                    for s, e, kind, length, modules in zip(
                        batch.beam_start[i, :n_beams],
                        batch.beam_end[i, :n_beams],
                        batch.beam_kind[i, :n_beams],
                        lengths,
                        own_modules(lengths),
                        strict=True,
                    )
                ],
                "f": json_floats(foot[i].T, 1),
            }
        cells.append(
            {
                "c": cell,
                "b": bins[i],
                "l": loss[i],
                "d": descriptors[i],
                "e": error[i],
                "k": [column[i] for column in k],
                "g": drawing,
            }
        )
        if walked:
            cells[-1]["w"] = [walked.get((cell, floor)) for floor in floors]
        if guessed:
            cells[-1]["p"] = [guessed.get((cell, floor)) for floor in floors]
        if predicted_loss[i]:
            cells[-1]["q"] = 1
        if i in parts:
            cells[-1]["r"] = parts[i]
    return {
        "run_id": trial.run_id,
        "trial_key": trial.trial_key,
        "approach": trial.approach,
        "fitness": trial.fitness,
        "mode": trial.mode,
        "descriptors": names,
        "resolution": resolution,
        "drawn": len(cells) if drawn is None else min(drawn, len(cells)),
        "floors": floors,
        "walk_s": walk_seconds(walks),
        "walk_model": model_run if guessed else None,
        "cells": cells,
    }


def real_parts(batch: LinkageBatch, motion: Motion, rows: np.ndarray) -> dict[int, dict]:
    """Returns, for the rows (indices into the batch, whose motion at the trial's angles is
    `motion`) that turn, their real parts as the
    page's r: {"p": [[part number, name, count], ...] for one leg, "j": 1 when a bar is
    built of joined beams} or {"x": why no real parts build it}. The build is the batch
    build (`sim.robot.builds`: the rounding `linkevo pull` builds), its layer plan and
    parts (`sim.robot.parts`)."""
    from linkevo.sim.robot.builds import lego_builds
    from linkevo.sim.robot.layers import LayerError, layer_plan
    from linkevo.sim.robot.parts import PartsError, assign_parts, catalogue

    if not len(rows):
        return {}
    here = take_rows(motion, rows) if motion.positions.shape[2] == DEFAULT_ANGLES else None
    built, rounded = lego_builds(take_rows(batch, rows), here)
    here = simulate(built, DEFAULT_ANGLES)
    cat = catalogue()
    out: dict[int, dict] = {}
    for j, row in enumerate(rows.tolist()):
        if not rounded[j] or not here.valid[j].all():
            out[row] = {"x": "no whole-module rounding of it turns"}
            continue
        try:
            plan = layer_plan(built, here, j)
            parts = assign_parts(built, here, plan, j)
        except (LayerError, PartsError) as exc:
            out[row] = {"x": str(exc)}
            continue
        counts = parts.counts(0)
        out[row] = {"p": [[n, cat.part(n).name, counts[n]] for n in sorted(counts)]}
        if parts.locks or (plan.width > 1).any():
            out[row]["j"] = 1
    return out


def _walked(walks: pd.DataFrame | None) -> tuple[list[str], dict[tuple[int, str], list]]:
    """Returns the floors of a walk map (flat first) and, per (cell, floor) walked, the
    page's [distance cm, breaks 0/1, reason, beyond the level-body bound 0/1, slides 0/1]."""
    if walks is None or walks.empty:
        return [], {}
    walks = walks[walks["status"] == Status.WALKED]
    floors = in_floor_order(walks["floor"].unique())
    walked = {
        (int(r["cell"]), str(r["floor"])): [
            round(float(r["mean_distance_cm"]), 1),
            int(bool(r["breaks"])),
            str(r["reason"]),
            int(beyond_bound_share(r) > 0),
            int(slide_share(r) > SLIDING_SHARE),
        ]
        for r in walks.to_dict("records")
    }
    return floors, walked


def with_prediction_map(
    table: pd.DataFrame, prediction: pd.DataFrame
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Returns a SAIL trial's walked map with the prediction map's cells it lacks (their
    loss minus the predicted value, `workers.walk_sail`), and the predicted walks of every
    predicted cell (a cell with a walk on a floor shows the walk there)."""
    shared = [c for c in table.columns if c in prediction.columns]
    extra = prediction.loc[~prediction["cell"].isin(table["cell"]), shared]
    extra = extra.assign(predicted_loss=True)
    table = pd.concat([table.assign(predicted_loss=False), extra], ignore_index=True)
    return table, prediction_rows(prediction)


def _predicted(predicted: pd.DataFrame | None) -> dict[tuple[int, str], list]:
    """Returns, per (cell, floor) predicted, the page's [predicted cm, spread cm, probability
    of breaking]."""
    if predicted is None or predicted.empty:
        return {}
    return {
        (int(cell), str(floor)): [round(float(d), 1), round(float(s), 1), round(float(p), 3)]
        for cell, floor, d, s, p in zip(
            predicted["cell"],
            predicted["floor"],
            predicted["predicted_cm"],
            predicted["spread_cm"],
            predicted["p_break"],
            strict=True,
        )
    }


def walk_seconds(walks: pd.DataFrame | None) -> float | None:
    """Returns how long a walk map's walks are (s): a `linkevo walkmap` walks 10 s (or its
    --seconds), a walking trial's search walks `sim.robot.walk_fitness.SEARCH_SECONDS`; None
    without a walk map."""
    if walks is None or walks.empty:
        return None
    return float(walks["seconds"].max())


def best_view(views: list[dict]) -> int:
    """Returns the index of the view the page opens on: the one holding the lowest loss
    among the views of the first fitness in the study's order (losses of different
    fitnesses do not compare); 0 when no view has a loss."""
    first = ordered({v["fitness"] for v in views}, FITNESSES)[:1]
    best = [
        (min(c["l"] for c in v["cells"] if c["l"] is not None), i)
        for i, v in enumerate(views)
        if v["fitness"] in first and any(c["l"] is not None for c in v["cells"])
    ]
    return min(best)[1] if best else 0


def render_page(title: str, views: list[dict]) -> str:
    """Returns the explorer page over one or more repertoire views (`repertoire_view`)."""
    template = (
        resources.files("linkevo.orchestrator").joinpath(TEMPLATE).read_text(encoding="utf-8")
    )
    blobs, index = [], []
    for i, view in enumerate(views):
        packed = gzip.compress(json.dumps(view, separators=(",", ":"), allow_nan=False).encode())
        blobs.append(
            f'<script type="application/octet-stream" id="trial-{i}">'
            f"{base64.b64encode(packed).decode('ascii')}</script>"
        )
        index.append(
            {
                "id": f"trial-{i}",
                "label": f"{view['trial_key']} ({len(view['cells'])} cells)",
                "run_id": view["run_id"],
            }
        )
    settings = {
        "node_kinds": NODE_KINDS,
        "beam_kinds": BEAM_KINDS,
        "toggle_deg": TOGGLE_DEG,
        "buildable_stretch": BUILDABLE_STRETCH,
        "unit_mm": DEFAULT_UNIT_MM,
        "trials": index,
        "first": best_view(views),
    }
    return (
        template.replace("{{TITLE}}", html.escape(title))
        .replace("{{SETTINGS}}", json.dumps(settings).replace("</", "<\\/"))
        .replace("{{DATA}}", "\n".join(blobs))
    )


def explore(
    store: RunStore,
    trials: list[TrialRun],
    out: Path,
    *,
    title: str,
    drawn: int | None = None,
    log_to: str | None = None,
    progress: Callable[[int, TrialRun], None] | None = None,
) -> Path:
    """Writes the explorer page of `trials` to `out` and returns it.

    Args:
        drawn: per trial, draw only the `drawn` lowest-loss cells (None: all).
        log_to: a run id to log the page to as `explorer.html` (None: do not log).
        progress: called with (trials done, trial) after each trial is read.
    """
    views = []
    with tempfile.TemporaryDirectory(prefix="linkevo-explore-") as tmp:
        for done, trial in enumerate(trials, 1):
            table = store.repertoire(trial.run_id, Path(tmp) / trial.run_id)
            walks = store.walk_map(trial.run_id, Path(tmp) / f"{trial.run_id}-walks")
            predicted = store.walk_prediction(trial.run_id, Path(tmp) / f"{trial.run_id}-pred")
            model_run = None
            if predicted is not None:
                model_run = store.tags(trial.run_id).get(layout.PREDICTED_BY)
            sail = store.prediction_map(trial.run_id, Path(tmp) / f"{trial.run_id}-sail")
            if sail is not None:
                table, predicted = with_prediction_map(table, sail)
                model_run = SAIL_MODEL
            views.append(repertoire_view(table, trial, drawn, walks, predicted, model_run))
            if progress is not None:
                progress(done, trial)
        write_bytes_atomic(out, render_page(title, views).encode("utf-8"))
        if log_to is not None:
            named = shutil.copyfile(
                out, Path(tmp) / layout.EXPLORER_HTML
            )  # the name it is logged as
            store.log_artefact(log_to, named)
    return out
