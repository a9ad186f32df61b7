"""The real driver stack (dynamixel-sdk on a pty, the gait's PID, the safety monitor)
against the bus emulator whose motors are the cranks of the robot simulated in MuJoCo
(`hardware.physics_bus`), in real time."""

from __future__ import annotations

import time

import numpy as np
import pytest

from linkevo.hardware import control_table as ct
from linkevo.hardware.errors import SafetyStop
from linkevo.hardware.physics_bus import PhysicsWorld
from linkevo.hardware.session import run_walk
from linkevo.sim.robot.hexapod import FLOORS, Motor
from tests.helpers.walking import jansen_leg


def _all_stopped(emu) -> None:
    for motor_id, state in emu.snapshots().items():
        assert state.goal_velocity == 0, f"motor {motor_id} still has a goal velocity"
        assert not state.torque_enabled, f"motor {motor_id} still has torque on"


def test_the_driver_walks_the_simulated_robot_with_loads_from_the_physics(emulator, config_for):
    world = PhysicsWorld(config_for("unused"), jansen_leg(), FLOORS["flat"])
    emu = emulator(motor_factory=world.motor_factory)
    start, loads, positions = world.body(), [], []

    def on_tick(record) -> None:
        loads.append([s.values["present_load"] for s in record.statuses.values()])
        positions.append([s.values["present_position"] for s in record.statuses.values()])

    result = run_walk(config_for(emu.port), 2.0, on_tick=on_tick)
    moved = world.body() - start
    assert result.ticks >= 90
    assert np.degrees(result.max_phase_error_rad) < 10.0
    assert moved[0] > 0.05  # metres forward: the legs push the robot along
    assert abs(moved[1]) < 0.5 * moved[0]
    loads = np.array(loads)
    assert (loads != 0).any() and np.unique(loads).size > 3  # read back from the physics
    # Present Position is the crank the physics turned: both tripods made most of a turn
    turned = np.abs(np.diff(np.array(positions)[[0, -1]], axis=0)) / ct.POSITION_UNITS_PER_TURN
    assert (turned > 0.8).all()
    _all_stopped(emu)


def test_a_stalled_motor_stops_the_walk_with_torque_off(emulator, config_for):
    """Motors far too weak for the robot stall at their torque limit: the motor raises its
    Overload error and the driver's hardware-error policy stops the walk."""
    weak = Motor(stall_nm=0.005)
    world = PhysicsWorld(config_for("unused"), jansen_leg(), FLOORS["flat"], motor=weak)
    emu = emulator(motor_factory=world.motor_factory)
    started = time.monotonic()
    with pytest.raises(SafetyStop, match=r"hardware error: overload"):
        run_walk(config_for(emu.port), 10.0)
    assert time.monotonic() - started < 8.0  # stopped well before the walk's end
    _all_stopped(emu)
    assert any(s.hardware_error & (1 << ct.OVERLOAD_BIT) for s in emu.snapshots().values())
