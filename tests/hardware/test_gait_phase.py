"""The tripod phase model and the PID on the wrapped phase error (pure, no bus)."""

from __future__ import annotations

import numpy as np
import pytest

from linkevo.hardware.config import GaitConfig, MotorConfig
from linkevo.hardware.gait import (
    PhaseController,
    alignment_goals,
    leg_phase,
    phase_separation,
    wrap,
)

MOTORS = (
    MotorConfig(id=1, direction=1, phase_deg=0.0, zero=100),
    MotorConfig(id=2, direction=-1, phase_deg=180.0, zero=0),
)
LIMITS = np.array([230, 230])


def test_wrap_maps_to_minus_pi_pi():
    assert np.allclose(
        wrap(np.array([0.0, 3 * np.pi, -3 * np.pi, 2 * np.pi - 0.1])), [0.0, -np.pi, -np.pi, -0.1]
    )


def test_leg_phase_uses_4096_per_turn_on_signed_multiturn_positions():
    zeros, directions = np.array([0, 0, 100]), np.array([1, -1, 1])
    phases = leg_phase(np.array([-1024, -1024, 4096 * 3 + 100 + 2048]), zeros, directions)
    assert np.allclose(phases, [1.5 * np.pi, 0.5 * np.pi, np.pi])


def test_alignment_goals_honour_zero_and_direction():
    assert alignment_goals(MOTORS).tolist() == [100, 2048]
    reversed_b = (MotorConfig(id=3, direction=-1, phase_deg=90.0, zero=0),)
    assert alignment_goals(reversed_b).tolist() == [3072]


def test_on_phase_legs_get_pure_feedforward_with_their_direction_sign():
    gait = GaitConfig(speed_rpm=30.0)
    controller = PhaseController(gait, MOTORS, LIMITS)
    controller.reset(0.0)
    units = controller.command(0.0, np.array([100, 2048]))
    assert units.tolist() == [131, -131]


def test_derivative_term_acts_on_a_changing_error():
    def second_command(kd):
        controller = PhaseController(
            GaitConfig(speed_rpm=0.0, kp=0.0, ki=0.0, kd=kd), MOTORS, LIMITS
        )
        controller.reset(0.0)
        controller.command(0.0, np.array([100, 2048]))
        return controller.command(0.1, np.array([100 - 200, 2048]))

    assert second_command(0.0).tolist() == [0, 0]
    assert second_command(0.5)[0] > 0


def test_command_is_clamped_to_the_velocity_limit():
    controller = PhaseController(GaitConfig(speed_rpm=50.0, kp=100.0), MOTORS, np.array([200, 50]))
    controller.reset(0.0)
    units = controller.command(0.0, np.array([100 - 1000, 2048 + 1000]))
    assert units.tolist() == [200, -50]


def test_phase_separation_of_two_tripods():
    phases = np.array([0.1, np.pi + 0.1, 0.1, np.pi + 0.1])
    tripod_a = np.array([True, False, True, False])
    assert phase_separation(phases, tripod_a) == pytest.approx(np.pi)
    assert phase_separation(np.array([0.5, 0.0]), np.array([True, False])) == pytest.approx(
        2 * np.pi - 0.5
    )


def walk_ideal_leg(gait: GaitConfig, seconds: float, held=(0.0, 0.0), lag_rpm: float = 0.0):
    """Returns the phase error in degrees at each 20 ms tick of one leg whose motor turns
    at the commanded speed less `lag_rpm`, except while `held` (start, end) stops it."""
    from linkevo.hardware.control_table import POSITION_UNITS_PER_TURN, VELOCITY_RPM_PER_UNIT

    motor = (MotorConfig(id=1, direction=1, phase_deg=0.0, zero=0),)
    controller = PhaseController(gait, motor, np.array([1023]))
    controller.reset(0.0)
    position, dt, errors = 0.0, 0.02, []
    for k in range(round(seconds / dt)):
        t = k * dt
        rpm = controller.command(t, np.array([round(position)]))[0] * VELOCITY_RPM_PER_UNIT
        if not held[0] <= t < held[1]:
            position += (rpm - lag_rpm) / 60.0 * POSITION_UNITS_PER_TURN * dt
        errors.append(np.degrees(controller.phase_errors(t + dt, np.array([round(position)]))[0]))
    return np.array(errors)


def test_a_leg_held_for_half_a_second_is_back_on_its_phase_soon_after():
    """Without the integral band the I term winds up during the hold and the catch-up,
    and the leg overshoots for kp / ki = 5 s (11° off 4.5 s after release)."""
    settled = abs(walk_ideal_leg(GaitConfig(), 7.1, held=(2.0, 2.5))[-1])
    wound_up = abs(walk_ideal_leg(GaitConfig(integral_band_deg=180.0), 7.1, held=(2.0, 2.5))[-1])
    assert settled < 3.0 < 8.0 < wound_up


def test_the_integral_still_removes_a_steady_lag():
    """A motor 2 rpm slower than commanded: P alone would leave 0.2 rad (11°) of error."""
    errors = walk_ideal_leg(GaitConfig(), 20.0, lag_rpm=2.0)
    assert abs(errors[-1]) < 1.0
    proportional_only = walk_ideal_leg(GaitConfig(ki=0.0), 20.0, lag_rpm=2.0)
    assert abs(proportional_only[-1]) > 8.0
