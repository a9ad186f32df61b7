"""Provides a walk's per-tick records (`WalkRecords`, preallocated for the walk loop of
`sim.robot.walking`) and the figures computed from them: heading (`yaw_of`, `wrap_angle`)
and the feet's slip (`foot_slip`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np


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


def yaw_of(mat: np.ndarray) -> float:
    return math.atan2(mat[3], mat[0])


def wrap_angle(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def foot_slip(feet: np.ndarray, contact: np.ndarray, t: np.ndarray) -> float:
    """Mean horizontal foot speed (mm/s) while a foot is down: its leg touches the floor
    and the foot is within 3 mm of the lowest height it reaches, over the feet (T, 6, 3)
    and contacts (T, 6) sampled at times t (T,)."""
    if len(t) < 2:
        return math.nan
    down = contact & (feet[:, :, 2] <= feet[:, :, 2].min(axis=0) + 0.003)
    both = down[1:] & down[:-1]
    dt = np.diff(t)[:, None]
    step = np.linalg.norm(np.diff(feet[:, :, :2], axis=0), axis=2) / np.where(dt > 0, dt, np.inf)
    return float(step[both].mean() * 1000) if both.any() else math.nan
