"""Provides `predict_table_one`: the study's prototyping (its Table I) repeated on the
simulated robot for one grid, by the paper's protocol.

For each MAP-Elites approach with F_p, for each of `trials_drawn` trials drawn by a seed
(the paper drew one trial's map at random):
- the **first robot** is the best F_p linkage of the drawn trial (`first="best"` takes
  the approach's best trial instead, drawn trials ignored);
- the **modified robot** comes from that trial's repertoire downsampled to 5 × 5 (the best
  linkage of each region, the map the paper's builders looked at), among the eight regions
  around the first robot's. By the default rule ("sought") it is the region whose path is
  nearest the first's among those with the change the paper's builders sought for that
  approach (`SOUGHT`), without looking at any walk; where no buildable neighbour has
  that change, the draw has no modified robot (its rows say "no modification possible",
  and no claim about the modified robot counts it). The rule "walked" takes the region
  whose linkage walks furthest on the flat floor, which builds the simulator's own
  ranking into every "modified against first" comparison.
Every robot is walked `repeats` × `seconds` on each floor on both robot models (lean and
full: the verdicts give both, so a reader sees where they disagree) and logged as
simulated field trials (robot "first" or "modified").
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
from linkevo.orchestrator.table_one_verdicts import NO_MODIFICATION
from linkevo.sim.errors import LinkevoError
from linkevo.sim.linkage.linkage_doc import to_document
from linkevo.sim.robot.hexapod import FLAT, FLOORS, ROBOT_MODELS
from linkevo.sim.robot.leg import LegError, leg_from_genome
from linkevo.sim.study import MAP_ELITES
from linkevo.workers.plots.repertoire import select_paths
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.linkages import LinkageRef, SourceLinkage, load_source
from linkevo.workers.store.runs import NotFound, RunStore, latest_per_trial

FITNESS = "Fp"
"""The study built robots from F_p repertoires only."""
FIRST_RULES: tuple[str, ...] = ("drawn", "best")
MODIFIED_RULES: tuple[str, ...] = ("sought", "walked")
SOUGHT: dict[str, tuple[str, str, int]] = {
    "MAP-WH": ("height", "a taller path (more lift)", +1),
    "MAP-LIS": ("mean_beam", "shorter beams", -1),
    "MAP-ST": ("width", "a wider path", +1),
    "MAP-AU": ("flatness", "a flatter bottom", +1),
}
"""Per approach: the trait (`path_traits`), in words, and the direction the paper's
builders moved it from the first robot to the modified one (Section V-B: a larger path
with higher lift; a smaller linkage with shorter beams; a slightly wider path; a flatter
bottom with the same lift)."""
BOTTOM_BAND = 0.1
"""A crank angle's foot is "along the bottom" within this share of the path's height
above its lowest point (`path_traits`' flatness)."""


@dataclass(frozen=True)
class StudyRobot:
    """One robot of the table: its approach, which draw and robot, and its linkage."""

    approach: str
    draw: int
    robot: str
    trial_key: str
    source: SourceLinkage
    region: tuple[int, int]
    rule: str


def path_traits(foot_x: np.ndarray, foot_y: np.ndarray, beams: list[dict]) -> dict[str, float]:
    """Returns what a builder sees of a linkage on the map: its foot path's width and
    height, its flatness (the share of crank angles whose foot lies within `BOTTOM_BAND`
    of the path's height above its lowest point) and its beams' mean length (modules).

    Args:
        foot_x, foot_y: the foot path (n_angles,), NaN where the linkage fails.
        beams: the linkage document's beams (each with a "length").
    """
    x, y = np.asarray(foot_x, dtype=float), np.asarray(foot_y, dtype=float)
    ok = np.isfinite(x) & np.isfinite(y)
    height = float(np.ptp(y[ok])) if ok.any() else 0.0
    bottom = y[ok] <= np.min(y[ok]) + BOTTOM_BAND * height if ok.any() else np.zeros(0)
    return {
        "width": float(np.ptp(x[ok])) if ok.any() else 0.0,
        "height": height,
        "flatness": float(bottom.mean()) if bottom.size else 0.0,
        "mean_beam": float(np.mean([b["length"] for b in beams])) if beams else 0.0,
    }


def path_distance(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> float:
    """Returns the mean distance between two foot paths (each (x, y), (n_angles,)) after
    centring each on its mean, over the crank angles where both assemble (inf: none)."""
    ax, ay, bx, by = (np.asarray(v, dtype=float) for v in (*a, *b))
    both = np.isfinite(ax) & np.isfinite(ay) & np.isfinite(bx) & np.isfinite(by)
    if not both.any():
        return float("inf")
    da = np.stack([ax - np.nanmean(ax), ay - np.nanmean(ay)])[:, both]
    db = np.stack([bx - np.nanmean(bx), by - np.nanmean(by)])[:, both]
    return float(np.linalg.norm(da - db, axis=0).mean())


def draw_trials(runs: pd.DataFrame, approach: str, k: int, seed: int) -> pd.DataFrame:
    """Returns `k` of the approach's finished trial runs drawn without replacement by
    `seed` (the same seed draws the same trials whatever else the grid holds)."""
    key_tag = f"tags.{layout.TRIAL_KEY}"
    trials = runs.sort_values(key_tag).reset_index(drop=True)
    if k > len(trials):
        raise StudyError(
            f"--trials-drawn {k} is invalid for {approach}: allowed 1..{len(trials)}, the "
            f"finished {FITNESS} trials it has"
        )
    rng = np.random.default_rng([seed, MAP_ELITES.index(approach)])
    return trials.iloc[np.sort(rng.choice(len(trials), size=k, replace=False))]


class StudyError(LinkevoError):
    """The study cannot be run as asked; says why before any walk."""


def _sources(first: SourceLinkage, regions: pd.DataFrame, mode: str) -> list[SourceLinkage]:
    return [
        SourceLinkage(
            run_id=first.run_id,
            cell=int(row["cell"]),
            experiment_id=first.experiment_id,
            approach=first.approach,
            fitness=FITNESS,
            document=to_document(np.asarray(row["genome"], dtype=float), mode),
            grid_id=first.grid_id,
        )
        for _, row in regions.iterrows()
    ]


def choose_modified(
    approach: str,
    start: pd.Series,
    near: pd.DataFrame,
    sources: list[SourceLinkage],
    rule: str,
    walk_flat: Callable[[SourceLinkage], dict],
    progress: Callable[[str], None],
) -> tuple[int | None, str]:
    """Returns the index in `near` of the modified robot's region (None: no modification
    possible) and the rule as applied.

    Args:
        start: the first robot's region row (foot_x, foot_y, genome).
        near: the regions around it, `sources` their linkages.
        rule: "sought" (no walk) or "walked" (`walk_flat` per candidate).
    """
    if rule == "walked":
        scored = []
        for i, source in enumerate(sources):
            result = walk_flat(source)
            distance = result["mean_distance_cm"]
            scored.append((not result["breaks"], -np.inf if distance is None else distance, i))
            progress(f"  candidate cell {source.cell} on flat: {walked_text(result)}")
        return max(scored)[2], "walked: the neighbour walking furthest on flat"
    trait, words, sign = SOUGHT[approach]
    mode = sources[0].document.get("mode", "paper") if sources else "paper"
    built = [i for i, s in enumerate(sources) if _builds(s.document["genome"], mode)]
    genome = np.asarray(start["genome"], dtype=float)
    base = path_traits(start["foot_x"], start["foot_y"], to_document(genome, mode)["beams"])
    paths = [(row.foot_x, row.foot_y) for row in near.itertuples()]
    has = [
        sign * (path_traits(*p, s.document["beams"])[trait] - base[trait]) > 0
        for p, s in zip(paths, sources, strict=True)
    ]
    pool = [i for i in built if has[i]]
    if not pool:
        return None, f"{NO_MODIFICATION}: no buildable neighbour has {words}"
    here = (start["foot_x"], start["foot_y"])
    nearest = min(pool, key=lambda i: path_distance(here, paths[i]))
    return nearest, f"sought: of the neighbours with {words}, the nearest path"


def _builds(genome: list[float], mode: str) -> bool:
    """Whether a leg can be built from the genome (it turns a full turn): a builder sees
    that on the bench, without walking it."""
    try:
        leg_from_genome(np.asarray(genome, dtype=float), mode)
    except LegError:
        return False
    return True


def choose_robots(
    store: RunStore,
    grid_id: str,
    *,
    config: RobotConfig,
    seconds: float,
    repeats: int,
    trials_drawn: int = 1,
    draw_seed: int = 0,
    first: str = "drawn",
    modified: str = "sought",
    progress: Callable[[str], None] = print,
) -> list[StudyRobot]:
    """Returns the first and the modified robot of each MAP-Elites approach in the grid,
    per drawn trial (module docstring)."""
    runs = latest_per_trial(store.trial_table(grid_id))
    if runs.empty:
        raise NotFound(f"grid {grid_id!r} has no trial runs in experiment {store.experiment!r}")
    approach_tag, fitness_tag, key_tag = (
        f"tags.{t}" for t in (layout.APPROACH, layout.FITNESS, layout.TRIAL_KEY)
    )
    runs = runs[(runs["status"] == "FINISHED") & (runs[fitness_tag] == FITNESS)]
    present = [a for a in MAP_ELITES if (runs[approach_tag] == a).any()]
    if not present:
        raise StudyError(
            f"grid {grid_id} has no finished MAP-Elites trial with {FITNESS}: Table I's robots "
            f"come from the {FITNESS} repertoires of {', '.join(MAP_ELITES)}; run such a grid "
            "(configs/paper.toml)"
        )
    if first == "best":
        chosen = {
            a: runs[runs[approach_tag] == a].sort_values(["metrics.best_loss", key_tag]).head(1)
            for a in present
        }
    else:
        chosen = {
            a: draw_trials(runs[runs[approach_tag] == a], a, trials_drawn, draw_seed)
            for a in present
        }  # every draw checked before the first walk

    def walk_flat(source: SourceLinkage) -> dict:
        return simulate_source(source, FLAT, config=config, seconds=seconds, repeats=repeats)[0]

    robots = []
    for approach, trials in chosen.items():
        for draw, (_, trial) in enumerate(trials.iterrows()):
            run_id, key = str(trial["run_id"]), str(trial[key_tag])
            source = load_source(store, LinkageRef(run_id))
            with tempfile.TemporaryDirectory() as tmp:
                table = store.repertoire(run_id, Path(tmp))
            mode = str(source.document.get("mode", "paper"))
            regions = select_paths(table, approach)
            start = regions.iloc[int(regions["loss"].to_numpy().argmin())]
            here = (int(start["row"]), int(start["col"]))
            robots.append(StudyRobot(approach, draw, "first", key, source, here, first))
            progress(f"{approach} draw {draw}: first robot {key} (run {run_id}), region {here}")
            near = regions[
                (np.abs(regions["row"] - here[0]) <= 1)
                & (np.abs(regions["col"] - here[1]) <= 1)
                & ~((regions["row"] == here[0]) & (regions["col"] == here[1]))
            ].reset_index(drop=True)
            pick, rule = None, f"{NO_MODIFICATION}: no neighbouring region is filled"
            if not near.empty:
                sources = _sources(source, near, mode)
                pick, rule = choose_modified(
                    approach, start, near, sources, modified, walk_flat, progress
                )
            if pick is None:
                robots.append(StudyRobot(approach, draw, "modified", key, source, here, rule))
                progress(f"  {rule}")
                continue
            spot = (int(near.loc[pick, "row"]), int(near.loc[pick, "col"]))
            robots.append(StudyRobot(approach, draw, "modified", key, sources[pick], spot, rule))
            progress(f"  modified robot: cell {sources[pick].cell}, region {spot}, {rule}")
    return robots


def predict_table_one(
    store: RunStore,
    grid_id: str,
    *,
    config: RobotConfig,
    seconds: float = 10.0,
    repeats: int = 5,
    trials_drawn: int = 1,
    draw_seed: int = 0,
    first: str = "drawn",
    modified: str = "sought",
    log: bool = True,
    progress: Callable[[str], None] = print,
) -> pd.DataFrame:
    """Returns Table I predicted for the grid: one row per approach, draw, robot, floor and
    robot model with the distances walked, whether it breaks and why, and where the
    linkage came from (`table_one_verdicts.judge_prototyping` judges the paper's claims
    on it)."""
    robots = choose_robots(
        store,
        grid_id,
        config=config,
        seconds=seconds,
        repeats=repeats,
        trials_drawn=trials_drawn,
        draw_seed=draw_seed,
        first=first,
        modified=modified,
        progress=progress,
    )
    rows = []
    for robot in robots:
        if robot.rule.startswith(NO_MODIFICATION):  # a row per floor and model, no walk
            rows += [_unmodified_row(robot, f, m) for f in FLOORS for m in ROBOT_MODELS]
            continue
        for floor in FLOORS:
            for model in ROBOT_MODELS:
                result, _ = simulate_source(
                    robot.source,
                    floor,
                    config=config,
                    seconds=seconds,
                    repeats=repeats,
                    model=model,
                )
                run_id = (
                    log_simulated(store.uri, robot.source, robot.robot, result, 0) if log else ""
                )
                rows.append(
                    {
                        "approach": robot.approach,
                        "draw": robot.draw,
                        "robot": robot.robot,
                        "floor": floor,
                        "model": model,
                        "mean_distance_cm": result["mean_distance_cm"],
                        "distance_cm": " ".join(f"{d:.1f}" for d in result["distance_cm"] if d),
                        "breaks": result["breaks"],
                        "reason": result["reason"],
                        "frailty": frailty_text(result.get("frailty")),
                        "caveats": "; ".join(result.get("caveats", [])),
                        "leg": result.get("leg", ""),
                        "bound_cm": result.get("bound_cm"),
                        "torque_p95_of_stall": result.get("torque_p95_of_stall"),
                        "pin_force_p99_n": result.get("pin_force_p99_n"),
                        "trial_key": robot.trial_key,
                        "source_run_id": robot.source.run_id,
                        "cell": "best" if robot.source.cell is None else robot.source.cell,
                        "region": f"{robot.region[0]},{robot.region[1]}",
                        "rule": robot.rule,
                        "field_trial_run_id": run_id,
                    }
                )
                progress(
                    f"{robot.approach} draw {robot.draw} {robot.robot} on {floor} ({model}): "
                    f"{walked_text(result)}"
                )
    return pd.DataFrame(rows)


def _unmodified_row(robot: StudyRobot, floor: str, model: str) -> dict[str, object]:
    """Returns the table row of a draw with no modified robot: its map and why, no walk."""
    return {
        "approach": robot.approach,
        "draw": robot.draw,
        "robot": robot.robot,
        "floor": floor,
        "model": model,
        "trial_key": robot.trial_key,
        "source_run_id": robot.source.run_id,
        "region": f"{robot.region[0]},{robot.region[1]}",
        "rule": robot.rule,
    }


def frailty_text(frailty: dict | None) -> str:
    """Returns a trial's frailty verdict with the ranges (over the parameters' ranges,
    `sim.robot.frailty`) of the foot's give and the motor axle's moment, e.g. "uncertain
    (give 14.1-30.2 mm, axle 410.0-520.3 N·mm)", or "" where none was judged."""
    if not frailty:
        return ""
    give, axle = frailty["give_mm"], frailty["axle_moment_nmm"]
    return f"{frailty['verdict']} (give {give[0]}-{give[2]} mm, axle {axle[0]}-{axle[2]} N·mm)"


def walked_text(result: dict) -> str:
    """Returns a simulated trial's outcome in words: its mean distance, or why it has
    none, and whether it breaks and why."""
    distance = result["mean_distance_cm"]
    text = "no distance" if distance is None else f"{distance:.1f} cm"
    return f"{text} (breaks: {result['reason']})" if result["breaks"] else text
