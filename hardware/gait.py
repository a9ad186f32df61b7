"""Provides the robot's side of the tripod gait: leg phases from motor positions, and
PhaseController, which runs the gait's PID (`sim.robot.gait`) in motor units.

Leg i's phase is `theta_i = 2*pi * ((d_i * (p_i - z_i)) mod 4096) / 4096`, where `p_i` is
the motor's signed multi-turn Present Position, `z_i` its calibrated zero and `d_i` its
mounting direction (+1 or -1). Its target is `phi_i(t) = 2*pi*f*(t - t0) + offset_i`; the
two tripods carry offsets 0 and pi, so tracking the clock keeps them half a turn apart.
"""

from __future__ import annotations

import numpy as np

from linkevo.hardware.config import GaitConfig, MotorConfig
from linkevo.hardware.control_table import POSITION_UNITS_PER_TURN, VELOCITY_RPM_PER_UNIT
from linkevo.sim.robot.gait import TWO_PI, PhasePid, wrap

__all__ = ["PhaseController", "alignment_goals", "leg_phase", "phase_separation", "wrap"]


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
    """The robot's side of the gait: `sim.robot.gait.PhasePid` on phases read from Present
    Position, its leg speeds turned into Goal Velocity units in each motor's frame.

    Args:
        gait: clock rate, speed and gains.
        motors: (N,) leg configs, in the order positions are passed.
        velocity_limits: (N,) each motor's Velocity Limit (0.229 rpm units).
    """

    def __init__(
        self, gait: GaitConfig, motors: tuple[MotorConfig, ...], velocity_limits: np.ndarray
    ) -> None:
        self._zeros = np.array([m.zero for m in motors], dtype=float)
        self._directions = np.array([m.direction for m in motors], dtype=float)
        self._pid = PhasePid(gait, np.array([m.phase_rad for m in motors]))
        self._limits = np.asarray(velocity_limits, dtype=float)

    def reset(self, t0: float) -> None:
        """Starts the clock at `t0` (seconds) and clears the PID state."""
        self._pid.reset(t0)

    def targets(self, t: float) -> np.ndarray:
        """Returns (N,) target phases at time `t`, in [0, 2*pi)."""
        return self._pid.targets(t)

    def phase_errors(self, t: float, positions: np.ndarray) -> np.ndarray:
        """Returns (N,) wrapped target-minus-measured phase errors in [-pi, pi)."""
        return self._pid.errors(t, leg_phase(positions, self._zeros, self._directions))

    def command(self, t: float, positions: np.ndarray) -> np.ndarray:
        """Returns (N,) integer Goal Velocities (motor frame, clamped to the limits).

        Args:
            t: the tick's time in seconds (same clock as `reset`).
            positions: (N,) signed Present Positions read this tick.
        """
        rpm = self._pid.rpm(t, leg_phase(positions, self._zeros, self._directions))
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
