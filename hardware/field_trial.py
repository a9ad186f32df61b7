"""Provides field trials: walk an evolved linkage's robot, log distances to MLflow, build Table I.

A field trial is one MLflow run (tag `linkevo.kind=field_trial`) in the source linkage's
experiment: the measured distances (metric `distance_cm`, one step per repeat, and
`mean_distance_cm`), the linkage document (`linkage.json`) and each repeat's telemetry.
Its param `simulated` says where it walked: on the robot, on the bus emulator (the driver's
dry run; distances typed in) or in the 3-D simulation (`linkevo hexapod simulate`,
distances predicted); the keys are the run layout's (`workers.store.run_layout`).
"""

from __future__ import annotations

import statistics
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from linkevo.hardware.config import RobotConfig
from linkevo.hardware.session import run_walk
from linkevo.sim.errors import LinkevoError
from linkevo.sim.study import MAP_ELITES, ROBOTS
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.linkages import SourceLinkage
from linkevo.workers.store.runs import RunStore

"""Row order of the study's Table I; other approaches follow alphabetically."""


class FieldTrialError(LinkevoError, ValueError):
    """Bad field-trial input: a bad distance, repeat count or robot name."""


def walk_repeats(
    config: RobotConfig,
    *,
    repeats: int,
    seconds: float,
    measure: Callable[[int], float],
    telemetry_dir: Path,
    simulate: bool = False,
) -> tuple[list[float], list[Path]]:
    """Walks `repeats` times and returns (distances in cm, telemetry CSV paths).

    Args:
        measure: called after repeat i (1-based) returns the measured distance in cm.
    """
    distances, files = [], []
    for repeat in range(1, repeats + 1):
        path = telemetry_dir / f"repeat_{repeat}.csv"
        run_walk(config, seconds, telemetry=path, simulate=simulate)
        files.append(path)
        distance = float(measure(repeat))
        if not np.isfinite(distance) or distance < 0:
            raise FieldTrialError(f"distance {distance} cm: allowed a finite value >= 0")
        distances.append(distance)
    return distances, files


def log_field_trial(
    uri: str,
    source: SourceLinkage,
    *,
    robot: str,
    floor: str,
    distances: list[float],
    params: dict[str, str],
    telemetry: tuple[Path, ...] | list[Path] = (),
    metrics: dict[str, float] | None = None,
    tags: dict[str, str] | None = None,
    artifacts: dict[str, dict] | None = None,
) -> str:
    """Logs one field-trial run in the source's experiment and returns its run id.

    Args:
        metrics, tags: more of either (a simulated trial's figures, its verdict).
        artifacts: JSON documents by artefact name.
    """
    store = RunStore.of_experiment(uri, source.experiment_id)
    tags = {
        layout.KIND: layout.FIELD_TRIAL,
        layout.SOURCE_RUN_ID: source.run_id,
        layout.SOURCE_CELL: "best" if source.cell is None else str(source.cell),
        layout.SOURCE_GRID: source.grid_id,
        layout.LINKAGE: linkage_key(source.document),
        layout.APPROACH: source.approach,
        layout.FITNESS: source.fitness,
        layout.ROBOT: robot,
        layout.FLOOR: floor,
        **(tags or {}),
    }
    run_id = store.create_run(f"field-{source.approach}-{robot}-{floor}", tags)
    try:
        store.log_params(run_id, params)
        for step, distance in enumerate(distances):
            store.log_metric(run_id, layout.DISTANCE_CM, distance, step=step)
        if distances:
            store.log_metric(run_id, layout.MEAN_DISTANCE_CM, statistics.fmean(distances))
        for name, value in (metrics or {}).items():
            store.log_metric(run_id, name, value)
        store.log_document(run_id, source.document, layout.LINKAGE_JSON)
        for name, document in (artifacts or {}).items():
            store.log_document(run_id, document, name)
        for path in telemetry:
            store.log_artefact(run_id, path, "telemetry" if path.suffix == ".csv" else "pictures")
    except BaseException as exc:  # a signal or a failure mid-log: never left RUNNING
        store.end_run(run_id, "KILLED", f"not logged whole: {type(exc).__name__} {exc}")
        raise
    store.end_run(run_id)
    return run_id


@dataclass(frozen=True)
class TableRow:
    """One row of Table I: an approach's robots from one grid (a field trial walks a
    linkage; the first and the modified robot are two linkages, and a row never pools
    trials of different linkages).

    Attributes:
        approach: the source trial's approach.
        grid: the source trial's grid id ("" for a linkage document without one).
        linkages: robot -> the linkage walked ("RUN_ID:CELL", or "document ab12..." for a
            document with no run), for the robots this row has trials of.
    """

    approach: str
    grid: str
    linkages: dict[str, str]

    @property
    def label(self) -> str:
        return f"{self.approach} (grid {self.grid})" if self.grid else self.approach


@dataclass(frozen=True)
class TrialTable:
    """Mean distance per row (an approach's linkages from one grid), robot and floor over
    every logged repeat.

    Attributes:
        rows: in the study's order of approaches, then by grid and first appearance.
        floors: column order within each robot (first seen first).
        means: (row index, robot, floor) -> mean distance in cm of the shown trials.
        counts: (row index, robot, floor) -> number of repeats.
        predicted: (row index, robot, floor) -> mean distance in cm predicted by the 3-D
            simulation, or "breaks" (shown beside the real trials).
        simulated: True when the table holds the emulator's dry runs instead of the real
            trials.
        left_out: field-trial runs not shown (the emulator's, or the real ones).
    """

    rows: tuple[TableRow, ...]
    floors: tuple[str, ...]
    means: dict[tuple[int, str, str], float]
    counts: dict[tuple[int, str, str], int]
    predicted: dict[tuple[int, str, str], float | str] = field(default_factory=dict)
    simulated: bool = False
    left_out: int = 0

    def format(self) -> str:
        """Returns the table as aligned text in the study's Table I layout (beside the
        real trials, each cell shows "real / predicted" where a prediction exists; "–" is
        a robot and floor with no trial), then the linkage each row's robots walked."""
        head = ["Approach"] + [f"{r.capitalize()} robot: {f}" for r in ROBOTS for f in self.floors]
        lines_ = [head]
        for i, row in enumerate(self.rows):
            cells = [row.label]
            for robot in ROBOTS:
                for floor in self.floors:
                    key = (i, robot, floor)
                    mean = self.means.get(key)
                    text = "–" if mean is None else f"{mean:.1f} cm"
                    if self.predicted:
                        guess = self.predicted.get(key)
                        guess = "–" if guess is None else guess
                        text += f" / {guess}" if isinstance(guess, str) else f" / {guess:.1f} cm"
                    cells.append(text)
            lines_.append(cells)
        widths = [max(len(r[i]) for r in lines_) for i in range(len(head))]
        text = [" | ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in lines_]
        text.insert(1, "-+-".join("-" * w for w in widths))
        text.append("– : no field trial of that robot on that floor. Linkages walked:")
        for row in self.rows:
            walked = ", ".join(f"{robot} robot {what}" for robot, what in row.linkages.items())
            text.append(f"  {row.label}: {walked}")
        return "\n".join(text)


def linkage_key(document: dict) -> str:
    """Returns a short digest of the linkage a document describes (its genome and mode):
    two field trials walked the same linkage when their keys agree."""
    import hashlib
    import json

    payload = json.dumps([document.get("mode", "paper"), document.get("genome")])
    return hashlib.sha1(payload.encode()).hexdigest()[:12]


def trial_table(uri: str, experiment: str, *, simulated: bool = False) -> TrialTable:
    """Returns the Table I summary of the experiment's real field trials beside the 3-D
    simulation's predictions for the same linkage, robot and floor, or with `simulated`
    the emulator's dry runs alone. Trials are grouped by the linkage they walked and its
    grid, never pooled across linkages."""
    store = RunStore(uri, experiment)
    runs = store.search(layout.where(layout.FIELD_TRIAL), order_by=["attributes.start_time ASC"])
    shown_kind = layout.EMULATOR if simulated else layout.REAL
    distances: dict[tuple[int, str, str], list[float]] = {}
    predicted: dict[tuple[int, str, str], list[float]] = {}
    broken: set[tuple[int, str, str]] = set()
    floors: list[str] = []
    rows: list[TableRow] = []
    left_out = 0
    for run in runs:
        kind = run.data.params.get(layout.SIMULATED, layout.REAL)
        if kind not in (shown_kind, layout.PHYSICS) or (simulated and kind == layout.PHYSICS):
            left_out += 1
            continue
        tags = run.data.tags
        floor, robot = tags.get(layout.FLOOR, "?"), tags.get(layout.ROBOT, "first")
        if floor not in floors:
            floors.append(floor)
        i = _row(
            rows,
            tags.get(layout.APPROACH, "unknown"),
            tags.get(layout.SOURCE_GRID, ""),
            robot,
            _walked(tags),
        )
        key = (i, robot, floor)
        history = list(store.metric_history(run.info.run_id, layout.DISTANCE_CM).values())
        if kind == layout.PHYSICS:
            predicted.setdefault(key, []).extend(history)
            if tags.get(layout.BREAKS) == "True":
                broken.add(key)
        else:
            distances.setdefault(key, []).extend(history)
    order = sorted(
        range(len(rows)),
        key=lambda i: (_approach_rank(rows[i].approach), rows[i].approach, rows[i].grid, i),
    )
    renumber = {old: new for new, old in enumerate(order)}

    def moved(table: dict) -> dict:
        return {(renumber[i], robot, floor): v for (i, robot, floor), v in table.items()}

    guesses: dict[tuple[int, str, str], float | str] = {
        k: statistics.fmean(v) for k, v in moved(predicted).items() if v
    }
    guesses |= dict.fromkeys(moved(dict.fromkeys(broken)), "breaks")
    return TrialTable(
        rows=tuple(rows[i] for i in order),
        floors=tuple(floors),
        means={k: statistics.fmean(v) for k, v in moved(distances).items() if v},
        counts={k: len(v) for k, v in moved(distances).items()},
        predicted=guesses,
        simulated=simulated,
        left_out=left_out,
    )


def _walked(tags: dict[str, str]) -> str:
    """How a table names the linkage a field trial walked: its source run and cell."""
    run_id, cell = tags.get(layout.SOURCE_RUN_ID, ""), tags.get(layout.SOURCE_CELL, "best")
    if run_id:
        return f"run {run_id}" + ("" if cell == "best" else f" cell {cell}")
    return f"document {tags.get(layout.LINKAGE, '?')}"


def _row(rows: list[TableRow], approach: str, grid: str, robot: str, walked: str) -> int:
    """Returns the index of the row that holds this robot's linkage: the first row of the
    approach and grid whose robot walked it, or has no such robot yet; else a new row."""
    for i, row in enumerate(rows):
        if (row.approach, row.grid) == (approach, grid) and row.linkages.get(robot) in (
            None,
            walked,
        ):
            row.linkages.setdefault(robot, walked)
            return i
    rows.append(TableRow(approach, grid, {robot: walked}))
    return len(rows) - 1


def _approach_rank(approach: str) -> int:
    """The study's Table I order (the MAP-Elites approaches), others after it."""
    return MAP_ELITES.index(approach) if approach in MAP_ELITES else len(MAP_ELITES)
