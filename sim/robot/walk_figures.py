"""Provides what a builder reads from walks: when a walked robot breaks (`break_reason`,
its limits and their reasoning in docs/walking.md) and the summary of field trials
(`summary`, Table I's figures over the repeats)."""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from linkevo.sim.robot.hexapod import LEG_SLOTS, Floor

if TYPE_CHECKING:
    from linkevo.sim.robot.walking import Walk

STALL_LAG_DEG = 45.0
"""A leg this far behind the clock with its motor at the supply limit has stalled."""
STALL_SATURATED = 0.05
"""... and its motor at the limit for at least this share of the walk."""
FRAME_DRAG_SHARE = 0.2
"""The frame touching the floor for more than this share of the walk: the legs cannot
carry it."""
PIN_FORCE_LIMIT_N = 60.0
"""The 99th-percentile pin force above which a LEGO Technic pin joint is taken to fail
(beams spread and the pin walks out); an estimate, see docs/walking.md."""
FOOT_DEVIATION_MM = 1.0
"""A foot further than this from where its linkage puts it is flagged (`caveats`)."""
PITCH_CAVEAT_DEG = 20.0
"""A frame pitching further than this is flagged: the robot rocks, and how far it gets
depends on contacts the simulation models least well (`caveats`)."""


@dataclass
class BreakWatch:
    """Says, while a walk of `ticks` control ticks goes on, when the break rules are
    certain to call it broken whatever its remaining ticks do: the frame has dragged for
    more than `FRAME_DRAG_SHARE` of the whole walk, a motor has been at its limit for
    `STALL_SATURATED` of it with its leg `STALL_LAG_DEG` behind, or so many pin forces
    exceed `PIN_FORCE_LIMIT_N` that the walk's 99th percentile must (numpy's linear
    percentile of n values is above the limit once n - floor(0.99 (n - 1)) of them are).

    Attributes:
        ticks: the walk's planned control ticks; pins_total: its planned pin forces (the
            load samples times the pins per sample).
    """

    ticks: int
    pins_total: int
    frame: int = 0
    limited: np.ndarray = field(default_factory=lambda: np.zeros(6, dtype=np.int64))
    lag_deg: np.ndarray = field(default_factory=lambda: np.zeros(6))
    pins_over: int = 0

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


def summary(walks: list[Walk], floor: Floor, seconds: float) -> dict:
    """Returns the JSON-able summary of field trials: distances in cm per repeat and their
    mean, and the builder's figures over the repeats (means, or the worst where a limit
    matters)."""

    def worst(values) -> float | None:
        finite = [v for v in values if math.isfinite(v)]
        return max(finite) if finite else None

    def mean(values) -> float | None:
        finite = [v for v in values if math.isfinite(v)]
        return statistics.fmean(finite) if finite else None

    distances = [w.distance_m * 100 for w in walks]
    broken = [w.reason for w in walks if w.breaks]
    reason = f"{broken[0]} ({len(broken)} of {len(walks)} walks break)" if broken else ""
    return {
        "floor": floor.name,
        "seconds": seconds,
        "distance_cm": [None if not math.isfinite(v) else round(v, 2) for v in distances],
        "mean_distance_cm": None if mean(distances) is None else round(mean(distances), 2),
        "bound_cm": None if mean(w.bound_m for w in walks) is None
        else round(mean(w.bound_m for w in walks) * 100, 2),
        "heading_drift_deg": [round(w.heading_drift_deg, 2) for w in walks],
        "beyond_bound": any(w.distance_m > w.bound_m for w in walks if math.isfinite(w.distance_m)),
        "breaks": any(w.breaks for w in walks),
        "reason": reason,
        "body_height_cm": rounded(mean(w.body_height_m * 100 for w in walks)),
        "min_clearance_cm": rounded(-worst(-w.clearance_m * 100 for w in walks)
                                   if worst(-w.clearance_m * 100 for w in walks) is not None
                                   else None),
        "max_pitch_deg": rounded(worst(w.max_pitch_deg for w in walks)),
        "max_roll_deg": rounded(worst(w.max_roll_deg for w in walks)),
        "foot_slip_mm_s": rounded(mean(w.foot_slip_mm_s for w in walks)),
        "torque_p95_of_stall": rounded(worst(w.torque_p95 for w in walks), 3),
        "torque_max_of_stall": rounded(worst(w.torque_max for w in walks), 3),
        "max_lag_deg": rounded(worst(w.max_lag_deg for w in walks)),
        "pin_force_p50_n": rounded(mean(w.pin_force_n[0] for w in walks)),
        "pin_force_p95_n": rounded(mean(w.pin_force_n[1] for w in walks)),
        "pin_force_p99_n": rounded(worst(w.pin_force_n[2] for w in walks)),
        "pin_force_max_n": rounded(worst(w.pin_force_n[3] for w in walks)),
        "loop_error_max_mm": rounded(worst(w.loop_error_mm for w in walks), 3),
        "foot_deviation_max_mm": rounded(worst(w.foot_deviation_mm for w in walks), 3),
        "timestep_ms": [round(w.timestep * 1000, 3) for w in walks],
        "frame_contact_share": rounded(worst(w.frame_contact for w in walks), 3),
        "frailty": frailest(walks),
        "caveats": caveats(walks),
    }  # fmt: skip


def frailest(walks: list[Walk]) -> dict | None:
    """Returns the frailty figures (`sim.robot.frailty.Frailty.as_dict`) of the walk whose leg
    gives most, or None when no walk has them (a walk that diverged)."""
    found = [w.frailty for w in walks if w.frailty is not None]
    if not found:
        return None
    return max(found, key=lambda f: (f.foot_deflection_mm, f.pin_moment_nmm)).as_dict()


def caveats(walks: list[Walk]) -> list[str]:
    """Returns what a builder should know before trusting these walks' distances (empty
    when nothing): a walk beyond the level-body no-slip bound, a frame that pitches past
    `PITCH_CAVEAT_DEG`, feet that stray past `FOOT_DEVIATION_MM` from their linkage's path."""
    out = []
    beyond = [w for w in walks if math.isfinite(w.distance_m) and w.distance_m > w.bound_m]
    if beyond:
        out.append(
            f"{len(beyond)} of {len(walks)} walks go beyond the level-body bound "
            f"({beyond[0].bound_m * 100:.0f} cm): the robot slides or hops forwards, which a "
            "LEGO robot on a real floor may not"
        )
    pitch = max((w.max_pitch_deg for w in walks if math.isfinite(w.max_pitch_deg)), default=0.0)
    if pitch > PITCH_CAVEAT_DEG:
        out.append(f"the frame pitches up to {pitch:.0f}°: the robot rocks, and its distance "
                   "rests on contacts the simulation models least well")  # fmt: skip
    stray = max((w.foot_deviation_mm for w in walks if math.isfinite(w.foot_deviation_mm)),
                default=0.0)  # fmt: skip
    if stray > FOOT_DEVIATION_MM:
        out.append(f"feet stray up to {stray:.1f} mm from their linkage's path (more than "
                   f"{FOOT_DEVIATION_MM:g} mm)")  # fmt: skip
    return out


def rounded(value: float | None, digits: int = 2) -> float | None:
    return None if value is None else round(float(value), digits)


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
