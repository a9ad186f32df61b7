"""Provides `PhysicsWorld`: the bus emulator's motors as the cranks of the simulated robot.

`linkevo hexapod walk --emulate physics` runs the real driver stack (dynamixel-sdk on the
pseudo-terminal, the gait's PID, the safety monitor) against `hardware.emulator.BusEmulator`
whose motors are `PhysicsMotor`s: what the driver writes (torque, operating mode, Goal
Velocity or Goal Position) drives the crank of the motor's leg in MuJoCo (the lean robot
model, `sim.robot.lean_model`), stepped in real time, and what it reads (Present Position,
Velocity and Load) comes from the physics. A leg that cannot carry the robot loads its
motor to the torque limit, so the driver's overload policy trips as it would on the robot.

Each motor drives the leg its config `name` names (`sim.robot.hexapod.LEG_SLOTS`); the robot is set
down with every leg at its phase offset, as a builder sets it down aligned. Its Present
Position is `zero + direction * phase * 4096 / 2pi`, the phase being the crank angle in the
linkage's frame, as `hardware.gait.leg_phase` reads it back. With torque off the crank is
held by the gearbox's friction (`HOLDING_NM`, an estimate: a 193:1 spur gearbox back-drives
only under a large torque).
"""

from __future__ import annotations

import math
import threading

import mujoco
import numpy as np

from linkevo.hardware import control_table as ct
from linkevo.hardware.config import RobotConfig
from linkevo.hardware.emulated_motor import EmulatedMotor
from linkevo.sim.robot.hexapod import LEG_SLOTS, Floor, Frame, Motor
from linkevo.sim.robot.lean_model import build_lean_robot
from linkevo.sim.robot.leg import Leg
from linkevo.sim.robot.model import control_tick
from linkevo.sim.robot.mounting import robot_spacers

HOLDING_NM = 0.5
"""Torque the gearbox of a motor with torque off holds before it back-drives (estimate)."""
OVERLOAD_S = 1.5
"""A motor at its torque limit this long raises its Overload error, as the MX-28 does."""
_RAD_S_PER_UNIT = ct.VELOCITY_RPM_PER_UNIT * 2 * math.pi / 60
_UNITS_PER_RAD = ct.POSITION_UNITS_PER_TURN / (2 * math.pi)
_TICK_S = 0.02  # the physics advances in chunks of at most this (the couplings' re-centring)


class PhysicsWorld:
    """The robot in MuJoCo, advanced to the bus's clock whenever a motor is read or written.

    Args:
        config: the robot config (its motors' names are the slots they drive).
        leg: the leg linkage on every slot.
        floor: the floor (`sim.robot.hexapod.FLOORS`), its contact as the config's `physics` says.
        frame, motor: the chassis and the motor model (defaults: the config's `physics`).
    """

    def __init__(
        self,
        config: RobotConfig,
        leg: Leg,
        floor: Floor,
        *,
        frame: Frame | None = None,
        motor: Motor | None = None,
    ) -> None:
        names = sorted(m.name for m in config.motors)
        if names != sorted(LEG_SLOTS):
            raise ValueError(
                f"the robot config's motors are named {names}; the physics mounts a leg where "
                f"its motor's name says, so name them {', '.join(LEG_SLOTS)}"
            )
        self.motor = motor or config.physics.motor()
        phases = {m.name: m.phase_rad for m in config.motors}  # set down aligned
        floor, frame = config.physics.floor(floor.name), frame or config.physics.frame()
        self.robot = build_lean_robot(
            dict.fromkeys(LEG_SLOTS, leg),
            phases,
            floor,
            frame=frame,
            motor=self.motor,
            spacers=robot_spacers(leg, config.robot()),  # mounted as a simulated walk is
        )
        self.model, self.data = self.robot.model, mujoco.MjData(self.robot.model)
        self.robot.loads.update(self.model, self.data)
        mujoco.mj_forward(self.model, self.data)
        self.slot_of = {m.id: LEG_SLOTS.index(m.name) for m in config.motors}
        self._mounts = {m.id: (m.direction, m.zero) for m in config.motors}
        self.motors: dict[int, PhysicsMotor] = {}
        self.lock = threading.Lock()
        self.t0: float | None = None

    def motor_factory(self, motor_id: int, *, now: float, **kwargs) -> PhysicsMotor:
        """Returns the bus emulator's motor `motor_id`, driving its leg's crank."""
        if self.t0 is None:
            self.t0 = now
        direction, zero = self._mounts[motor_id]
        motor = PhysicsMotor(self, motor_id, direction, zero, now=now, **kwargs)
        self.motors[motor_id] = motor
        return motor

    def advance(self, now: float) -> None:
        """Steps the physics to `now` (seconds on the bus's clock) with the motors' current
        commands: each crank's speed goal and torque limits, or the gearbox's hold."""
        with self.lock:
            m, d, robot = self.model, self.data, self.robot
            target = now - (self.t0 if self.t0 is not None else now)
            step = m.opt.timestep
            while d.time + step / 2 < target:
                chunk = max(1, min(round(_TICK_S / step), round((target - d.time) / step)))
                goal = d.ctrl[robot.actuators].copy()
                for motor_id, motor in self.motors.items():
                    i = self.slot_of[motor_id]
                    act, dof = robot.actuators[i], robot.crank_dof[i]
                    if motor.torque_on:
                        goal[i] = motor.direction * motor.commanded_units() * _RAD_S_PER_UNIT
                        m.actuator_forcerange[act] = (-self.motor.stall_nm, self.motor.stall_nm)
                        m.dof_damping[dof] = self.motor.back_emf_damping
                    else:  # the drive off: the gearbox holds, no back-EMF
                        goal[i] = 0.0
                        m.actuator_forcerange[act] = (-HOLDING_NM, HOLDING_NM)
                        m.dof_damping[dof] = 0.0
                control_tick(robot, d, goal, chunk)

    def crank(self, motor_id: int) -> tuple[float, float, float]:
        """Returns (phase rad, speed rad/s, torque N·m) of the motor's crank, in the
        linkage's counter-clockwise sense."""
        with self.lock:
            i = self.slot_of[motor_id]
            robot, d = self.robot, self.data
            return (
                float(robot.start_phases[i] + d.qpos[robot.crank_qpos[i]]),
                float(d.qvel[robot.crank_dof[i]]),
                float(robot.motor_torque(d)[i]),
            )

    def body(self) -> np.ndarray:
        """Returns (3,) the frame's position (m)."""
        with self.lock:
            return self.data.xpos[self.robot.frame_body].copy()


class PhysicsMotor(EmulatedMotor):
    """An emulated MX-28 whose shaft is a crank of the simulated robot: its position,
    speed and load are the physics', its commands drive the crank."""

    def __init__(
        self,
        world: PhysicsWorld,
        motor_id: int,
        direction: int,
        zero: int,
        *,
        now: float,
        **kwargs,
    ) -> None:
        self.world, self.direction, self.zero = world, direction, zero
        self._offset = 0.0  # position re-wraps (as the firmware does) shift the count
        self._limit_since: float | None = None
        super().__init__(motor_id, now=now, **kwargs)
        self.position = self._physics_position()

    def commanded_units(self) -> float:
        """The shaft speed the firmware would command now, in 0.229 rpm units."""
        return EmulatedMotor._velocity(self)

    def _physics_position(self) -> float:
        phase, _, _ = self.world.crank(self.motor_id)
        return self.zero + self.direction * phase * _UNITS_PER_RAD + self._offset

    def _integrate(self, dt: float) -> None:
        self.world.advance(self.last_update + dt)
        self.position = self._physics_position()
        self.temperature += self.heating_c_per_s * dt
        if self.temperature > self.value(ct.TEMPERATURE_LIMIT):
            self.set_hardware_error(1 << 2)

    def _rewrap(self) -> None:
        before = self.position
        super()._rewrap()
        self._offset += self.position - before

    def _refresh_present(self, velocity: float) -> None:
        _, speed, torque = self.world.crank(self.motor_id)
        super()._refresh_present(self.direction * speed / _RAD_S_PER_UNIT)
        load = self.direction * torque / self.world.motor.stall_nm * 1000
        self._store(ct.PRESENT_LOAD, max(-1000, min(1000, round(load))))
        motor = self.world.motor
        no_load = motor.no_load_rpm * 2 * math.pi / 60
        limit = abs(torque) >= 0.98 * motor.stall_nm * (1 - abs(speed) / no_load)
        if not (self.torque_on and limit):
            self._limit_since = None
        elif self._limit_since is None:
            self._limit_since = self.last_update
        elif self.last_update - self._limit_since >= OVERLOAD_S:
            self.set_hardware_error(1 << ct.OVERLOAD_BIT)
