"""Provides TickRecord and TelemetryWriter: one CSV row per control tick, written atomically."""

from __future__ import annotations

import contextlib
import csv
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from linkevo.hardware import control_table as ct
from linkevo.hardware.bus import Status
from linkevo.workers.store.artifacts import atomic_path


@dataclass(frozen=True)
class TickRecord:
    """What one control tick read and commanded.

    Attributes:
        time_s: seconds since the walk's clock started.
        statuses: motor id -> the sync-read values of that tick.
        goal_velocities: motor id -> Goal Velocity written (0.229 rpm units).
    """

    time_s: float
    statuses: Mapping[int, Status]
    goal_velocities: Mapping[int, int]


COLUMNS_PER_MOTOR = ("position", "velocity_rpm", "load_percent", "temperature_c")


def header(motor_ids: list[int]) -> list[str]:
    """Returns the CSV header: time_s, then m<id>_<column> for every motor."""
    return ["time_s"] + [f"m{i}_{c}" for i in motor_ids for c in COLUMNS_PER_MOTOR]


def row(record: TickRecord, motor_ids: list[int]) -> list[str]:
    """Returns the CSV cells of one tick (position in raw units, the rest in SI-like units)."""
    cells = [f"{record.time_s:.4f}"]
    for motor_id in motor_ids:
        v = record.statuses[motor_id].values
        cells += [
            str(v[ct.PRESENT_POSITION.name]),
            f"{ct.units_to_rpm(v[ct.PRESENT_VELOCITY.name]):.3f}",
            f"{v[ct.PRESENT_LOAD.name] * ct.LOAD_PERCENT_PER_UNIT:.1f}",
            str(v[ct.PRESENT_TEMPERATURE.name]),
        ]
    return cells


class TelemetryWriter:
    """Streams rows to a temp file beside `path` and moves it into place on close
    (`workers.store.artifacts.atomic_path`: fsynced, readable as the umask allows).

    Closing also happens after an error or a stop, so a partial walk keeps its rows; a
    walk that never ticked (a bad port, a missing motor) leaves an existing `path` as it
    was rather than replacing it with a header.
    """

    def __init__(self, path: str | Path, motor_ids: list[int]) -> None:
        self.path = Path(path)
        self._ids = list(motor_ids)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._commit = contextlib.ExitStack()
        self._tmp = self._commit.enter_context(atomic_path(self.path))
        self._file = open(self._tmp, "w", newline="", encoding="utf-8")  # noqa: SIM115
        self._csv = csv.writer(self._file)
        self._csv.writerow(header(self._ids))
        self.rows = 0

    def __call__(self, record: TickRecord) -> None:
        """Writes one tick's row."""
        self._csv.writerow(row(record, self._ids))
        self.rows += 1

    def close(self) -> None:
        """Closes the file and, when it holds a row, atomically replaces `path` with it
        (idempotent)."""
        if self._file.closed:
            return
        self._file.close()
        if not self.rows:
            self._tmp.unlink()
        self._commit.close()

    def __enter__(self) -> TelemetryWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
