"""Provides the study's hexapod as the 3-D walk simulates it: leg slots, frame, motors,
LEGO beams and the two floors of the paper's Table I.

Every number here is either from a datasheet (the MX-28AT's) or an estimate of the
study's robot, which the paper does not measure; `docs/walking.md` gives the source or
the reasoning of each. Lengths are in metres unless a name says otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ROBOT_MODELS: tuple[str, ...] = ("lean", "full")
"""The MuJoCo models of the robot a walk can run on (`sim.walking.MODELS`): lean, the
default, and full."""
WALK_SECONDS = 10.0
"""How long a walk lasts unless told: Table I's 10 s."""
LEG_SLOTS = ("left-front", "left-middle", "left-rear", "right-front", "right-middle", "right-rear")
"""Where a leg is mounted; a motor's `name` in the robot config picks its slot."""
TRIPOD_OFFSETS_DEG = {
    "left-front": 180.0,
    "left-rear": 180.0,
    "right-middle": 180.0,
    "left-middle": 0.0,
    "right-front": 0.0,
    "right-rear": 0.0,
}
"""The alternating tripod of `configs/hexapod.toml`, by slot."""

UNIT_M = 0.008
"""One linkage unit: one LEGO Technic module (8 mm hole pitch)."""
LAYER_PITCH_M = 0.008
"""Out-of-plane distance between two layers of beams (a Technic beam is one module thick)."""
BEAM_RADIUS_M = 0.0036
"""Half the width of a Technic beam (7.2 mm)."""
BEAM_KG_PER_MODULE = 0.0003
"""A Technic beam's mass per module of length (a 15-module beam weighs about 4.5 g)."""


@dataclass(frozen=True)
class Motor:
    """The MX-28AT at 12 V as a DC motor: torque `stall * (v/voltage - w/w0)` for a supply
    voltage v in [-voltage, voltage] and speed w, w0 the no-load speed (datasheet: 2.5 N·m
    stall, 55 rpm no load at 12 V). Its firmware velocity loop sets
    `v = ke * (w_goal + loop_gain * (w_goal - w))`, clipped to the supply.

    The torque is `kt/R * clip(v, -voltage, voltage) - b * w`, b = kt/R * ke the back-EMF's
    damping: the drive `clip(drive_gain * w_goal - drive_bias * w, -stall, stall)` less
    `b * w`. Unclipped, that is a velocity servo, torque `servo_gain * (w_goal - w)`;
    clipped, the torque-speed line (`speed_at`). MuJoCo integrates both parts at every
    physics step (`sim.robot_model.add_motor`): the drive as the crank's actuator (its gain,
    its velocity bias and its force range), the back-EMF as the crank's joint damping, so
    a braked crank turns on the datasheet's line whatever the control tick."""

    stall_nm: float = 2.5
    no_load_rpm: float = 55.0
    voltage: float = 12.0
    velocity_limit_rpm: float = 230 * 0.229
    loop_gain: float = 4.0
    armature: float = 0.002

    @property
    def ke(self) -> float:
        """Back-EMF constant, volts per rad/s."""
        return self.voltage / (self.no_load_rpm * 2.0 * math.pi / 60.0)

    @property
    def kt_over_r(self) -> float:
        """Torque per volt at stall, N·m per volt."""
        return self.stall_nm / self.voltage

    @property
    def servo_gain(self) -> float:
        """Torque per rad/s of speed error of the unclipped velocity loop, N·m·s/rad."""
        return self.kt_over_r * self.ke * (1.0 + self.loop_gain)

    @property
    def back_emf_damping(self) -> float:
        """b: the back-EMF's torque per rad/s (kt/R * ke), N·m·s/rad."""
        return self.kt_over_r * self.ke

    @property
    def drive_gain(self) -> float:
        """The drive's torque per rad/s of speed goal (before the supply's clip)."""
        return self.servo_gain

    @property
    def drive_bias(self) -> float:
        """The drive's torque per rad/s of speed (the loop's feedback, before the clip)."""
        return self.back_emf_damping * self.loop_gain

    def speed_at(self, torque: np.ndarray) -> np.ndarray:
        """Returns the speed (rad/s) on the torque-speed line at full supply for a load
        torque (N·m): the datasheet's line."""
        w0 = self.no_load_rpm * 2.0 * math.pi / 60.0
        return w0 * (1.0 - np.asarray(torque, dtype=float) / self.stall_nm)


@dataclass(frozen=True)
class Frame:
    """The chassis as one box: six motors, the 3-D printed frame and the metal stiffening
    rod. Leg axles sit at the box's mid height, `leg_spacing` apart along it; a leg's first
    layer of beams is `leg_plane` outside the box's side."""

    length: float = 0.38
    width: float = 0.12
    height: float = 0.05
    mass_kg: float = 1.1
    leg_spacing: float = 0.16
    leg_plane: float = 0.012


@dataclass(frozen=True)
class Floor:
    """A floor's contact: its friction coefficient (it wins over the beams': the floor has
    the higher `priority`) and MuJoCo's solref (time constant s, damping ratio) and solimp,
    which set how far a foot sinks in (a time constant below twice the physics step is
    raised to it)."""

    name: str
    friction: float
    solref: tuple[float, float]
    solimp: tuple[float, float, float]
    summary: str


FLAT, CARPET = "flat", "carpet"
"""The floors' names: the paper's "flat and slightly slippery" floor and its thick carpet."""
FLOORS = {
    FLAT: Floor(
        FLAT,
        friction=0.35,
        solref=(0.004, 1.0),
        solimp=(0.95, 0.99, 0.001),
        summary="flat and slightly slippery: plastic on a smooth floor, stiff contact",
    ),
    CARPET: Floor(
        CARPET,
        friction=0.9,
        solref=(0.02, 1.0),
        solimp=(0.5, 0.9, 0.006),
        summary="a thick carpet: high friction, feet sink a few millimetres",
    ),
}


def in_floor_order(names) -> list[str]:
    """Returns floor names in `FLOORS`' order (flat first), unknown names last, sorted."""
    names = set(names)
    return [f for f in FLOORS if f in names] + sorted(names - set(FLOORS))


def floor(name: str) -> Floor:
    """Returns the named floor.

    Raises:
        ValueError: naming the floor and the ones there are.
    """
    if name not in FLOORS:
        raise ValueError(f"floor {name!r}: allowed {', '.join(FLOORS)}")
    return FLOORS[name]
