"""Provides a walk's records (`WalkRecords`, preallocated per control tick) and its break
rules followed as it goes (`WalkWatch`), for the walk loop of `sim.robot.walking`."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from linkevo.sim.robot.walk_figures import BreakWatch


@dataclass
class WalkRecords:
    """A walk's per-tick records, preallocated for its T ticks (S of them sampling loads).

    Attributes:
        t: (T,) time; body: (T, 3) frame position; mat: (T, 9) frame orientation;
        phase: (T, 6) crank phases; qpos: (T, nq) the state; torque: (T, 6) motor torques;
        limited: (T, 6) each drive at its supply's limit; feet: (T, 6, 3) foot sites; frame:
        (T,) the frame
        touches the floor; contact: (T, 6) each leg touches it; loads: (S, width) the
        model's load samples (`sim.robot.model.LegLoads`).
    """

    t: np.ndarray
    body: np.ndarray
    mat: np.ndarray
    phase: np.ndarray
    qpos: np.ndarray
    torque: np.ndarray
    limited: np.ndarray
    feet: np.ndarray
    frame: np.ndarray
    contact: np.ndarray
    loads: np.ndarray

    def head(self, ticks: int, every: int) -> WalkRecords:
        """Returns the first `ticks` ticks' records (and their load samples, one every
        `every` ticks)."""
        rows = {f.name: getattr(self, f.name)[:ticks] for f in dataclasses.fields(self)}
        return WalkRecords(**{**rows, "loads": self.loads[: -(-ticks // every)]})

    @classmethod
    def empty(cls, ticks: int, samples: int, nq: int, width: int) -> WalkRecords:
        return cls(
            t=np.empty(ticks),
            body=np.empty((ticks, 3)),
            mat=np.empty((ticks, 9)),
            phase=np.empty((ticks, 6)),
            qpos=np.empty((ticks, nq)),
            torque=np.empty((ticks, 6)),
            limited=np.zeros((ticks, 6), dtype=bool),
            feet=np.empty((ticks, 6, 3)),
            frame=np.zeros(ticks, dtype=bool),
            contact=np.zeros((ticks, 6), dtype=bool),
            loads=np.empty((samples, width)),
        )


class WalkWatch:
    """A walk's break rules followed as it goes (`sim.robot.walk_figures.BreakWatch`), with the
    pin forces of the samples so far (computed once, kept for the walk's figures)."""

    def __init__(self, ticks: int, samples: int) -> None:
        self.samples = samples
        self.rules = BreakWatch(ticks, 0)
        self._ticks = 0
        self._samples = 0
        self._pins: list[np.ndarray] = []

    def follow(
        self,
        rec: WalkRecords,
        ticks: int,
        samples: int,
        pin_forces: Callable[[np.ndarray], np.ndarray],
        lag_deg: Callable[[np.ndarray, np.ndarray], np.ndarray],
    ) -> None:
        """Takes the records up to `ticks` ticks and `samples` load samples.

        Args:
            pin_forces: the robot's pin forces (flat) of load samples (`LegLoads`).
            lag_deg: (6,) each leg's largest lag behind the clock over ticks' times (k,)
                and phases (k, 6).
        """
        new = slice(self._ticks, ticks)
        pins = pin_forces(rec.loads[self._samples : samples])
        if self._samples == 0 and samples:
            self.rules.pins_total = len(pins) // samples * self.samples
        lag = lag_deg(rec.t[new], rec.phase[new])
        self.rules.add(rec.frame[new], rec.limited[new], lag, pins)
        self._pins.append(pins)
        self._ticks, self._samples = ticks, samples

    def pins(self) -> np.ndarray:
        """Every pin force over the samples followed (flat)."""
        return np.concatenate(self._pins) if self._pins else np.zeros(0)
