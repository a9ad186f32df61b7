"""Provides simulated field trials: a tracked or pulled linkage walked on the 3-D robot
(`sim.robot.walking`) with the real robot's gait from its config, summarised as Table I reads it,
and logged as a field trial marked `simulated=physics`."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from linkevo.hardware.field_trial import log_field_trial
from linkevo.sim.linkage.linkage_doc import DocumentError, from_document
from linkevo.sim.robot.field_summary import summary
from linkevo.sim.robot.leg import LegError, leg_from_genome
from linkevo.sim.robot.walk_rows import AS_EVOLVED, LEGO_BUILD
from linkevo.sim.robot.walking import Walk, WalkSettings, field_trials
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.artifacts import read_document
from linkevo.workers.store.linkages import SourceLinkage

if TYPE_CHECKING:
    from linkevo.hardware.config import RobotConfig

FIGURES = (
    "bound_cm",
    "body_height_cm",
    "min_clearance_cm",
    "max_pitch_deg",
    "max_roll_deg",
    "foot_slip_mm_s",
    "torque_p95_of_stall",
    "torque_max_of_stall",
    "max_lag_deg",
    "pin_force_p50_n",
    "pin_force_p95_n",
    "pin_force_p99_n",
    "pin_force_max_n",
    "loop_error_max_mm",
    "frame_contact_share",
)
"""The builder's figures of a simulated trial, logged as metrics."""


def document_source(path: Path, experiment_id: str) -> SourceLinkage:
    """Returns a linkage document file (`linkevo pull`'s linkage.json) as a source.

    Raises:
        ValueError: a file that is not a readable linkage document, naming it.
    """
    document = read_document(path)
    try:
        from_document(document)
    except DocumentError as exc:
        raise DocumentError(f"{path}: not a linkage document ({exc})") from exc
    meta = document.get("meta", {})
    return SourceLinkage(
        run_id=str(meta.get("run_id") or ""),
        cell=meta.get("cell"),
        experiment_id=experiment_id,
        approach=str(meta.get("approach") or "unknown"),
        fitness=str(meta.get("fitness") or "unknown"),
        document=document,
        grid_id=str(meta.get("grid_id") or ""),
    )


def simulate_source(
    source: SourceLinkage,
    floor_name: str,
    *,
    config: RobotConfig,
    seconds: float,
    repeats: int,
    seed: int = 0,
    model: str = "lean",
) -> tuple[dict, list[Walk]]:
    """Walks the source's linkage `repeats` times on the floor and returns the summary
    (`sim.robot.walking.summary`, with how the leg was built and the robot model,
    `sim.robot.walking.MODELS`) and the walks; a linkage that does not turn comes back as `breaks`
    with no distances and no walks."""
    genome, mode = from_document(source.document)
    robot = config.robot()
    where = robot.physics.floor(floor_name)
    try:
        leg = leg_from_genome(genome, mode)
    except LegError as exc:
        refused = {
            "floor": where.name,
            "seconds": seconds,
            "distance_cm": [],
            "mean_distance_cm": None,
            "heading_drift_deg": [],
            "breaks": True,
            "reason": str(exc),
            "leg": "none",
            "model": model,
        }
        return refused, []
    walks = field_trials(
        leg,
        where,
        repeats=repeats,
        seed=seed,
        settings=WalkSettings(seconds=seconds, model=model),
        robot=robot,
    )
    result = summary(walks, where, seconds)
    result["model"] = model
    result["leg"] = LEGO_BUILD if leg.built else AS_EVOLVED
    if leg.note:
        result["leg_note"] = leg.note
    return result, walks


def write_pictures(walk: Walk, out: Path, title: str) -> list[Path]:
    """Writes the first walk's pictures into out: walk.gif (its first 4 s), walk.png,
    path.png and contacts.png (`workers.plots.walk`, drawn without OpenGL); returns their
    paths."""
    from linkevo.workers.plots import walk as draw

    out.mkdir(parents=True, exist_ok=True)
    frames = draw.render_frames(walk, seconds=4.0, fps=12.0, size=(400, 225))
    return [
        draw.write_gif(frames, out / "walk.gif", fps=12.0),
        draw.write_still(frames[len(frames) // 2], out / "walk.png"),
        draw.draw_body_path(walk, out / "path.png", title),
        draw.draw_contacts(walk, out / "contacts.png"),
    ]


def log_simulated(
    uri: str,
    source: SourceLinkage,
    robot: str,
    result: dict,
    seed: int,
    pictures: list[Path] = (),
) -> str:
    """Logs a simulated field trial (param simulated=physics), with its pictures, and
    returns its run id."""
    distances = [d for d in result["distance_cm"] if d is not None]
    metrics = {
        name: float(result[name])
        for name in FIGURES
        if result.get(name) is not None and math.isfinite(result[name])
    }
    return log_field_trial(
        uri,
        source,
        robot=robot,
        floor=result["floor"],
        distances=distances,
        params={
            layout.SIMULATED: layout.PHYSICS,
            layout.SECONDS: str(result["seconds"]),
            "repeats": str(len(result["distance_cm"])),
            "seed": str(seed),
            "leg": result.get("leg", ""),
            "model": result.get("model", ""),
        },
        metrics=metrics,
        tags={layout.BREAKS: str(result["breaks"]), layout.REASON: result["reason"][:5000]},
        artifacts={"simulated_trial.json": result},
        telemetry=list(pictures),
    )
