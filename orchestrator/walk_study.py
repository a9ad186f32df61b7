"""Provides `predict_table_one`: the study's prototyping (its Table I) repeated on the
simulated robot for one grid.

For each MAP-Elites approach with F_p, as the paper did:
- the **first robot** is the best F_p linkage of the approach's best trial (the trial
  whose best loss is lowest, as `linkevo pull GRID --best` would take it);
- the **modified robot** is chosen from that trial's repertoire downsampled to 5 × 5 (the
  best linkage of each region, the map the paper's builders looked at): of the regions
  next to the first robot's (the eight around it), the one whose linkage walks furthest on
  the flat floor without breaking (or, if all break, furthest). The paper's builders chose
  by eye a change they believed would help; the simulation makes the same kind of local
  move on the map, but by walking the candidates.
Both are then walked `repeats` × `seconds` on each floor and logged as simulated field
trials (robot "first" or "modified").
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.hardware.config import RobotConfig
from linkevo.orchestrator.simulated_trials import log_simulated, simulate_source
from linkevo.sim.linkage_doc import to_document
from linkevo.sim.robot import FLAT, FLOORS
from linkevo.sim.study import MAP_ELITES
from linkevo.workers.plots.repertoire import select_paths
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.linkages import LinkageRef, SourceLinkage, load_source
from linkevo.workers.store.runs import NotFound, RunStore, latest_per_trial

FITNESS = "Fp"
"""The study built robots from F_p repertoires only."""


@dataclass(frozen=True)
class Robot:
    """One robot of the table: its approach, which robot, and the linkage it stands on."""

    approach: str
    robot: str
    trial_key: str
    source: SourceLinkage
    region: tuple[int, int]


def choose_robots(
    store: RunStore,
    grid_id: str,
    *,
    config: RobotConfig,
    seconds: float,
    repeats: int,
    model: str = "lean",
    progress: Callable[[str], None] = print,
) -> list[Robot]:
    """Returns the first and the modified robot of each MAP-Elites approach in the grid."""
    runs = latest_per_trial(store.trial_table(grid_id))
    if runs.empty:
        raise NotFound(f"grid {grid_id!r} has no trial runs in experiment {store.experiment!r}")
    approach_tag, fitness_tag, key_tag = (
        f"tags.{t}" for t in (layout.APPROACH, layout.FITNESS, layout.TRIAL_KEY)
    )
    runs = runs[(runs["status"] == "FINISHED") & (runs[fitness_tag] == FITNESS)]
    robots = []
    for approach in MAP_ELITES:
        trials = runs[runs[approach_tag] == approach]
        if trials.empty:
            continue
        best = trials.sort_values(["metrics.best_loss", key_tag]).iloc[0]
        run_id, key = str(best["run_id"]), str(best[key_tag])
        first = load_source(store, LinkageRef(run_id))
        with tempfile.TemporaryDirectory() as tmp:
            table = store.repertoire(run_id, Path(tmp))
        mode = str(first.document.get("mode", "paper"))
        regions = select_paths(table, approach)
        start = regions.iloc[int(regions["loss"].to_numpy().argmin())]
        here = (int(start["row"]), int(start["col"]))
        robots.append(Robot(approach, "first", key, first, here))
        progress(f"{approach}: first robot {key} (run {run_id}), region {here} of the 5 × 5 map")
        near = regions[
            (np.abs(regions["row"] - here[0]) <= 1)
            & (np.abs(regions["col"] - here[1]) <= 1)
            & ~((regions["row"] == here[0]) & (regions["col"] == here[1]))
        ]
        scored = []
        for _, row in near.iterrows():
            source = SourceLinkage(
                run_id=run_id,
                cell=int(row["cell"]),
                experiment_id=first.experiment_id,
                approach=approach,
                fitness=FITNESS,
                document=to_document(np.asarray(row["genome"], dtype=float), mode),
                grid_id=first.grid_id,
            )
            result, _ = simulate_source(
                source, FLAT, config=config, seconds=seconds, repeats=repeats, model=model
            )
            distance = result["mean_distance_cm"]
            scored.append(
                (not result["breaks"], -np.inf if distance is None else distance, source, row)
            )
            progress(
                f"  candidate cell {row['cell']} in region ({row['row']}, {row['col']}) on "
                f"flat: {walked_text(result)}"
            )
        if scored:
            _, _, source, row = max(scored, key=lambda s: (s[0], s[1]))
            robots.append(
                Robot(approach, "modified", key, source, (int(row["row"]), int(row["col"])))
            )
    return robots


def predict_table_one(
    store: RunStore,
    grid_id: str,
    *,
    config: RobotConfig,
    seconds: float = 10.0,
    repeats: int = 5,
    model: str = "lean",
    log: bool = True,
    progress: Callable[[str], None] = print,
) -> pd.DataFrame:
    """Returns Table I predicted for the grid: one row per approach, robot and floor with
    the distances walked, whether it breaks and why, and where the linkage came from."""
    robots = choose_robots(
        store, grid_id, config=config, seconds=seconds, repeats=repeats, model=model,
        progress=progress,
    )  # fmt: skip
    rows = []
    for robot in robots:
        for floor in FLOORS:
            result, _ = simulate_source(
                robot.source, floor, config=config, seconds=seconds, repeats=repeats, model=model
            )
            run_id = log_simulated(store.uri, robot.source, robot.robot, result, 0) if log else ""
            rows.append(
                {
                    "approach": robot.approach,
                    "robot": robot.robot,
                    "floor": floor,
                    "mean_distance_cm": result["mean_distance_cm"],
                    "distance_cm": " ".join(f"{d:.1f}" for d in result["distance_cm"] if d),
                    "breaks": result["breaks"],
                    "reason": result["reason"],
                    "leg": result.get("leg", ""),
                    "bound_cm": result.get("bound_cm"),
                    "torque_p95_of_stall": result.get("torque_p95_of_stall"),
                    "pin_force_p99_n": result.get("pin_force_p99_n"),
                    "trial_key": robot.trial_key,
                    "source_run_id": robot.source.run_id,
                    "cell": "best" if robot.source.cell is None else robot.source.cell,
                    "region": f"{robot.region[0]},{robot.region[1]}",
                    "field_trial_run_id": run_id,
                }
            )
            progress(f"{robot.approach} {robot.robot} on {floor}: {walked_text(result)}")
    return pd.DataFrame(rows)


def walked_text(result: dict) -> str:
    """Returns a simulated trial's outcome in words: its mean distance, or why it has
    none, and whether it breaks and why."""
    distance = result["mean_distance_cm"]
    text = "no distance" if distance is None else f"{distance:.1f} cm"
    return f"{text} (breaks: {result['reason']})" if result["breaks"] else text
