"""Provides when a walked robot breaks: the rules (a stalled motor, a dragging frame, pin
loads above a LEGO pin joint's), each a documented limit (docs/walking.md, "When a robot
breaks"), judged on a whole walk (`break_reason`) or followed as it goes (`BreakWatch`, for
a walk that stops at its break). Frail legs are judged apart (`sim.robot.frailty`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from linkevo.sim.robot.hexapod import LEG_SLOTS

if TYPE_CHECKING:
    from linkevo.sim.robot.leg import Leg
    from linkevo.sim.robot.walk_records import WalkRecords
    from linkevo.sim.robot.walking import Walk

STALL_LAG_DEG = 45.0
"""A leg this far behind the clock with its motor at the supply limit has stalled."""
STALL_SATURATED = 0.05
"""... and its motor at the limit for at least this share of the walk."""
FRAME_DRAG_SHARE = 0.2
"""The frame touching the floor for more than this share of the walk: the legs cannot
carry it."""
INVALID_DEVIATION_MM = 10.0
"""A walk whose feet stray further than this from where their linkage puts them came apart:
the model did not hold the legs together (a foot 10 mm off its path is a module and a
quarter; a walk that holds together keeps its feet within about 1 mm, `LOOP_ERROR_BOUND_MM`
of `sim.robot.walking`). Such a walk is invalid: it breaks with that reason and has no
distance (docs/walking.md, "Where the lean model breaks down")."""
PIN_FORCE_LIMIT_N = 60.0
"""The 99th-percentile pin force above which a LEGO Technic pin joint is taken to fail
(beams spread and the pin walks out); an estimate, see docs/walking.md."""


@dataclass
class BreakWatch:
    """Says, while a walk of `ticks` control ticks goes on, when the break rules are
    certain to call it broken whatever its remaining ticks do: the frame has dragged for
    more than `FRAME_DRAG_SHARE` of the whole walk, a motor has been at its limit for
    `STALL_SATURATED` of it with its leg `STALL_LAG_DEG` behind, or so many pin forces
    exceed `PIN_FORCE_LIMIT_N` that the walk's 99th percentile must (numpy's linear
    percentile of n values is above the limit once n - floor(0.99 (n - 1)) of them are).

    It follows a walk's records as they grow (`follow`), keeping the pin forces of the
    samples so far (computed once, kept for the walk's figures: `pins`).

    Attributes:
        ticks: the walk's planned control ticks; samples: its planned load samples.
        pins_total: its planned pin forces (the load samples times the pins per sample).
    """

    ticks: int
    samples: int
    pins_total: int = 0
    frame: int = 0
    limited: np.ndarray = field(default_factory=lambda: np.zeros(6, dtype=np.int64))
    lag_deg: np.ndarray = field(default_factory=lambda: np.zeros(6))
    pins_over: int = 0
    _followed: tuple[int, int] = (0, 0)
    _pins: list[np.ndarray] = field(default_factory=list)

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
        done_ticks, done_samples = self._followed
        new = slice(done_ticks, ticks)
        pins = pin_forces(rec.loads[done_samples:samples])
        if done_samples == 0 and samples:
            self.pins_total = len(pins) // samples * self.samples
        self.add(rec.frame[new], rec.limited[new], lag_deg(rec.t[new], rec.phase[new]), pins)
        self._pins.append(pins)
        self._followed = (ticks, samples)

    def pins(self) -> np.ndarray:
        """Every pin force over the samples followed (flat)."""
        return np.concatenate(self._pins) if self._pins else np.zeros(0)

    def add(self, frame: np.ndarray, limited: np.ndarray, lag_deg: np.ndarray, pins: np.ndarray):
        """Takes the next ticks' records: frame (k,) and limited (k, 6) bool, the legs'
        largest lag over them (6,) in degrees, and the pin forces they sampled (flat, N)."""
        self.frame += int(frame.sum())
        self.limited += limited.sum(axis=0)
        self.lag_deg = np.maximum(self.lag_deg, lag_deg)
        self.pins_over += int((pins > PIN_FORCE_LIMIT_N).sum())

    def broken(self) -> bool:
        """Whether the walk breaks, whatever its remaining ticks do."""
        stalled = (self.lag_deg > STALL_LAG_DEG) & (self.limited >= STALL_SATURATED * self.ticks)
        n = self.pins_total
        return bool(
            self.frame > FRAME_DRAG_SHARE * self.ticks
            or stalled.any()
            or (n > 0 and self.pins_over >= n - math.floor(0.99 * (n - 1)))
        )


def invalid_reason(walk: Walk, model: str, legs: Iterable[Leg]) -> str:
    """Returns why a walk is invalid ("" when it is not): its feet strayed past
    `INVALID_DEVIATION_MM` from their linkage's path. The reason names the legs' fastest
    joint (`Leg.fastest_joint_mm_per_deg`): the legs whose walks come apart are mostly legs
    near a toggle."""
    if not walk.foot_deviation_mm > INVALID_DEVIATION_MM:
        return ""
    fastest = max(leg.fastest_joint_mm_per_deg() for leg in legs)
    return (
        f"invalid: the {model} model came apart, its feet strayed {walk.foot_deviation_mm:.0f} mm "
        f"from their linkage's path (more than {INVALID_DEVIATION_MM:g} mm); not a walk (the "
        f"leg's fastest joint moves {fastest:.0f} mm per crank degree)"
    )


def break_reason(walk: Walk, lag_deg: np.ndarray) -> str:
    """Returns why a walked robot breaks ("" when it does not): a stalled motor, a frame
    that drags, or pin loads above what a LEGO pin joint holds.

    Args:
        walk: the walk's figures.
        lag_deg: (6,) how far each leg fell behind the clock.
    """
    reasons = []
    stalled = (lag_deg > STALL_LAG_DEG) & (walk.saturated >= STALL_SATURATED)
    for i in np.flatnonzero(stalled):
        reasons.append(
            f"the {LEG_SLOTS[i]} motor stalls: at its torque limit for "
            f"{walk.saturated[i]:.0%} of the walk, the leg falls {lag_deg[i]:.0f}° behind "
            "the clock"
        )
    if walk.frame_contact > FRAME_DRAG_SHARE:
        reasons.append(
            f"the frame drags on the floor for {walk.frame_contact:.0%} of the walk: the "
            "legs cannot carry it"
        )
    if walk.pin_force_n[2] > PIN_FORCE_LIMIT_N:
        reasons.append(
            f"pin loads reach {walk.pin_force_n[2]:.0f} N (99th percentile), above the "
            f"{PIN_FORCE_LIMIT_N:.0f} N a LEGO Technic pin joint holds"
        )
    return "; ".join(reasons)
