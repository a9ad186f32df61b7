"""Provides the tripod gait: its settings and the phase PID, one definition for the real
robot (`hardware/`) and the simulated one (`sim.robot.walking`).

A leg's phase is its crank angle in the linkage's own frame (the spec's counter-clockwise
crank angle), whatever way its motor is mounted. Leg i's target is
`phi_i(t) = 2*pi * speed_rpm/60 * (t - t0) + offset_i`; the two tripods carry offsets 0
and pi. The command is a leg speed in rpm, `speed_rpm + kp*e + ki*int(e) + kd*de/dt` on
the wrapped phase error e; the robot turns it into Goal Velocity units and the simulation
into its motor model's speed goal.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

TWO_PI = 2.0 * np.pi


def limits(
    low: float | None = None, high: float | None = None, *, open_high: bool = False
) -> dict[str, object]:
    """Returns the field metadata a config loader checks a value against: [low, high]
    (or [low, high) with `open_high`), None for no bound."""
    return {"low": low, "high": high, "open_high": open_high}


def range_error(key: str, value: float, meta: dict) -> str | None:
    """Returns what is wrong with `value` against a field's `limits` ("KEY = VALUE is out
    of range [LOW, HIGH]", or "... is not a finite number" for NaN and infinities, which
    every comparison would let through), or None when it is within them."""
    low, high = meta.get("low"), meta.get("high")
    if not math.isfinite(value):
        return f"{key} = {value!r} is not a finite number"
    too_high = high is not None and (value >= high if meta["open_high"] else value > high)
    if (low is not None and value < low) or too_high:
        bracket = ")" if meta.get("open_high") else "]"
        return f"{key} = {value!r} is out of range [{low}, {high}{bracket}"
    return None


@dataclass(frozen=True)
class GaitConfig:
    """Clock rate, leg speed and the PID on the wrapped phase error (`[gait]` of the robot
    config). Gains map a phase error in radians to a leg-speed correction in rpm."""

    rate_hz: float = field(default=50.0, metadata=limits(1.0, 500.0))
    speed_rpm: float = field(default=25.0, metadata=limits(-60.0, 60.0))
    kp: float = field(default=10.0, metadata=limits(0.0))
    ki: float = field(default=2.0, metadata=limits(0.0))
    kd: float = field(default=0.2, metadata=limits(0.0))
    integral_limit_rpm: float = field(default=10.0, metadata=limits(0.0))
    integral_band_deg: float = field(default=15.0, metadata=limits(0.0, 180.0))
    max_lag_s: float = field(default=0.25, metadata=limits(0.0))


GAIT_KEYS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(GaitConfig))
"""The names `[gait]` and a grid's `gait` table accept."""


def wrap(angle: np.ndarray) -> np.ndarray:
    """Returns angles wrapped to [-pi, pi). Shape preserved."""
    return (np.asarray(angle, dtype=float) + np.pi) % TWO_PI - np.pi


class PhasePid:
    """The leg-speed command of each leg: velocity feedforward plus a PID on its wrapped
    phase error.

    Args:
        gait: clock rate, speed and gains.
        offsets: (N,) each leg's phase offset in radians (0 or pi for a tripod gait).
    """

    def __init__(self, gait: GaitConfig, offsets: np.ndarray) -> None:
        self.gait = gait
        self._offsets = np.asarray(offsets, dtype=float)
        n = len(self._offsets)
        self._t0 = 0.0
        self._last_t: float | None = None
        self._last_error = np.zeros(n)
        self._integral = np.zeros(n)

    def reset(self, t0: float) -> None:
        """Starts the clock at `t0` (seconds) and clears the PID state."""
        self._t0 = t0
        self._last_t = None
        self._last_error[:] = 0.0
        self._integral[:] = 0.0

    def targets(self, t: float) -> np.ndarray:
        """Returns (N,) target phases at time `t`, in [0, 2*pi)."""
        turns = self.gait.speed_rpm / 60.0 * (t - self._t0)
        return np.mod(TWO_PI * turns + self._offsets, TWO_PI)

    def errors(self, t: float, phases: np.ndarray) -> np.ndarray:
        """Returns (N,) wrapped target-minus-measured phase errors in [-pi, pi)."""
        return wrap(self.targets(t) - np.asarray(phases, dtype=float))

    def rpm(self, t: float, phases: np.ndarray) -> np.ndarray:
        """Returns (N,) leg speeds in rpm (leg frame, unclamped).

        Args:
            t: the tick's time in seconds (same clock as `reset`).
            phases: (N,) measured leg phases in radians.
        """
        gait = self.gait
        error = self.errors(t, phases)
        dt = 0.0 if self._last_t is None else t - self._last_t
        derivative = np.zeros_like(error)
        if dt > 0.0:
            # Integrate only near the clock: a leg that was held or slipped far behind
            # would otherwise wind the integral up and overshoot for kp / ki seconds.
            near = np.abs(error) <= math.radians(gait.integral_band_deg)
            self._integral += np.where(near, error * dt, 0.0)
            if gait.ki > 0.0:
                bound = gait.integral_limit_rpm / gait.ki
                np.clip(self._integral, -bound, bound, out=self._integral)
            derivative = wrap(error - self._last_error) / dt
        self._last_t = t
        self._last_error = error
        return gait.speed_rpm + gait.kp * error + gait.ki * self._integral + gait.kd * derivative
