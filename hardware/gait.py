"""Provides the tripod phase model and PhaseController, the PID that keeps legs on the clock.

Leg i's phase is `theta_i = 2*pi * ((d_i * (p_i - z_i)) mod 4096) / 4096`, where `p_i` is
the motor's signed multi-turn Present Position, `z_i` its calibrated zero and `d_i` its
mounting direction (+1 or -1). Its target is `phi_i(t) = 2*pi*f*(t - t0) + offset_i`; the
two tripods carry offsets 0 and pi, so tracking the clock keeps them half a turn apart.
"""

from __future__ import annotations

import numpy as np

from hardware.config import GaitConfig, MotorConfig
from hardware.control_table import POSITION_UNITS_PER_TURN, VELOCITY_RPM_PER_UNIT

TWO_PI = 2.0 * np.pi


def wrap(angle: np.ndarray) -> np.ndarray:
    """Returns angles wrapped to [-pi, pi). Shape preserved."""
    return (np.asarray(angle, dtype=float) + np.pi) % TWO_PI - np.pi


def leg_phase(positions: np.ndarray, zeros: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Returns each leg's phase in [0, 2*pi).

    Args:
        positions: (N,) signed multi-turn Present Position, 4096 units per turn.
        zeros: (N,) calibrated zero positions.
        directions: (N,) +1 or -1.
    """
    turns = np.mod(directions * (np.asarray(positions) - zeros), POSITION_UNITS_PER_TURN)
    return turns * (TWO_PI / POSITION_UNITS_PER_TURN)


def alignment_goals(motors: tuple[MotorConfig, ...]) -> np.ndarray:
    """Returns (N,) Goal Positions in [0, 4096) that put each leg at its phase offset."""
    zeros = np.array([m.zero for m in motors])
    directions = np.array([m.direction for m in motors])
    offsets = np.array([m.phase_deg for m in motors]) / 360.0 * POSITION_UNITS_PER_TURN
    return np.mod(np.round(zeros + directions * offsets), POSITION_UNITS_PER_TURN).astype(int)


class PhaseController:
    """Velocity feedforward plus a PID on each leg's wrapped phase error.

    Args:
        gait: clock rate, speed and gains.
        motors: (N,) leg configs, in the order positions are passed.
        velocity_limits: (N,) each motor's Velocity Limit (0.229 rpm units).
    """

    def __init__(
        self, gait: GaitConfig, motors: tuple[MotorConfig, ...], velocity_limits: np.ndarray
    ) -> None:
        self._gait = gait
        self._zeros = np.array([m.zero for m in motors], dtype=float)
        self._directions = np.array([m.direction for m in motors], dtype=float)
        self._offsets = np.array([m.phase_rad for m in motors])
        self._limits = np.asarray(velocity_limits, dtype=float)
        self._t0 = 0.0
        self._last_t: float | None = None
        self._last_error = np.zeros(len(motors))
        self._integral = np.zeros(len(motors))

    def reset(self, t0: float) -> None:
        """Starts the clock at `t0` (seconds) and clears the PID state."""
        self._t0 = t0
        self._last_t = None
        self._last_error[:] = 0.0
        self._integral[:] = 0.0

    def targets(self, t: float) -> np.ndarray:
        """Returns (N,) target phases at time `t`, in [0, 2*pi)."""
        turns = self._gait.speed_rpm / 60.0 * (t - self._t0)
        return np.mod(TWO_PI * turns + self._offsets, TWO_PI)

    def phase_errors(self, t: float, positions: np.ndarray) -> np.ndarray:
        """Returns (N,) wrapped target-minus-measured phase errors in [-pi, pi)."""
        return wrap(self.targets(t) - leg_phase(positions, self._zeros, self._directions))

    def command(self, t: float, positions: np.ndarray) -> np.ndarray:
        """Returns (N,) integer Goal Velocities (motor frame, clamped to the limits).

        Args:
            t: the tick's time in seconds (same clock as `reset`).
            positions: (N,) signed Present Positions read this tick.
        """
        gait = self._gait
        error = self.phase_errors(t, positions)
        dt = 0.0 if self._last_t is None else t - self._last_t
        derivative = np.zeros_like(error)
        if dt > 0.0:
            # Integrate only near the clock: a leg that was held or slipped far behind
            # would otherwise wind the integral up and overshoot for kp / ki seconds.
            near = np.abs(error) <= np.radians(gait.integral_band_deg)
            self._integral += np.where(near, error * dt, 0.0)
            if gait.ki > 0.0:
                bound = gait.integral_limit_rpm / gait.ki
                np.clip(self._integral, -bound, bound, out=self._integral)
            derivative = wrap(error - self._last_error) / dt
        self._last_t = t
        self._last_error = error
        rpm = gait.speed_rpm + gait.kp * error + gait.ki * self._integral + gait.kd * derivative
        units = np.round(self._directions * rpm / VELOCITY_RPM_PER_UNIT)
        return np.clip(units, -self._limits, self._limits).astype(int)


def phase_separation(phases: np.ndarray, tripod_a: np.ndarray) -> float:
    """Returns the mean phase of the legs not in `tripod_a` minus those in it, in [0, 2*pi).

    Args:
        phases: (N,) leg phases in radians.
        tripod_a: (N,) bool, True for legs of the first tripod.
    """
    mean_a = np.angle(np.exp(1j * phases[tripod_a]).mean())
    mean_b = np.angle(np.exp(1j * phases[~tripod_a]).mean())
    return float(np.mod(mean_b - mean_a, TWO_PI))
