"""Provides the study's hexapod as the 3-D walk simulates it: leg slots, frame, motors,
LEGO beams and the two floors of the paper's Table I.

Every number here is either from a datasheet (the MX-28AT's) or an estimate of the
study's robot, which the paper does not measure; `docs/walking.md` gives the source or
the reasoning of each. Lengths are in metres unless a name says otherwise.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from linkevo.sim.robot.gait import GaitConfig, limits, range_error

ROBOT_MODELS: tuple[str, ...] = ("lean", "full")
"""The MuJoCo models of the robot a walk can run on (`sim.robot.walking.MODELS`): lean, the
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
    physics step (`sim.robot.model.add_motor`): the drive as the crank's actuator (its gain,
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


@dataclass(frozen=True)
class Physics:
    """The simulated robot's physical parameters a builder may know better than linkevo
    (`[physics]` of the robot config, `hardware.config`): the frame, the motor and the
    floors. The defaults are the study's robot as estimated (`Frame`, `Motor`, `FLOORS`;
    `docs/walking.md`); `linkevo hexapod calibrate` fits chosen ones to a robot's own
    field trials. Lengths in metres, masses in kg; a floor's `*_contact_s` is the time
    constant of its contact's softness (MuJoCo's solref; larger: feet sink further)."""

    frame_mass_kg: float = field(default=Frame.mass_kg, metadata=limits(0.1, 20.0))
    frame_length_m: float = field(default=Frame.length, metadata=limits(0.1, 2.0))
    frame_width_m: float = field(default=Frame.width, metadata=limits(0.02, 1.0))
    frame_height_m: float = field(default=Frame.height, metadata=limits(0.01, 0.5))
    leg_spacing_m: float = field(default=Frame.leg_spacing, metadata=limits(0.02, 1.0))
    motor_stall_nm: float = field(default=Motor.stall_nm, metadata=limits(0.1, 20.0))
    motor_no_load_rpm: float = field(default=Motor.no_load_rpm, metadata=limits(1.0, 600.0))
    motor_loop_gain: float = field(default=Motor.loop_gain, metadata=limits(0.0, 100.0))
    flat_friction: float = field(default=FLOORS[FLAT].friction, metadata=limits(0.01, 3.0))
    carpet_friction: float = field(default=FLOORS[CARPET].friction, metadata=limits(0.01, 3.0))
    flat_contact_s: float = field(default=FLOORS[FLAT].solref[0], metadata=limits(0.0005, 0.2))
    carpet_contact_s: float = field(default=FLOORS[CARPET].solref[0], metadata=limits(0.0005, 0.2))

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"physics {f.name} = {value!r}: allowed a number")
            wrong = range_error(f.name, float(value), f.metadata)
            if wrong:
                raise ValueError(f"physics {wrong}")

    @classmethod
    def of(cls, values: dict) -> Physics:
        """Returns the robot with `values` (names from `PHYSICS_KEYS`) changed from the
        study's.

        Raises:
            ValueError: naming an unknown key or a value out of its range.
        """
        unknown = sorted(set(values) - set(PHYSICS_KEYS))
        if unknown:
            raise ValueError(f"physics: unknown key(s) {unknown}; allowed: {list(PHYSICS_KEYS)}")
        return cls(**values)

    def frame(self) -> Frame:
        """Returns the chassis these parameters describe."""
        return dataclasses.replace(
            Frame(),
            mass_kg=self.frame_mass_kg,
            length=self.frame_length_m,
            width=self.frame_width_m,
            height=self.frame_height_m,
            leg_spacing=self.leg_spacing_m,
        )

    def motor(self) -> Motor:
        """Returns the motor these parameters describe."""
        return dataclasses.replace(
            Motor(),
            stall_nm=self.motor_stall_nm,
            no_load_rpm=self.motor_no_load_rpm,
            loop_gain=self.motor_loop_gain,
        )

    def floor(self, name: str) -> Floor:
        """Returns the named floor with these parameters' friction and softness.

        Raises:
            ValueError: naming the floor and the ones there are.
        """
        base = floor(name)
        friction = getattr(self, f"{name}_friction")
        softness = getattr(self, f"{name}_contact_s")
        return dataclasses.replace(base, friction=friction, solref=(softness, base.solref[1]))

    def changed(self) -> dict[str, float]:
        """Returns the parameters that differ from the defaults (what identifies a robot
        other than the study's)."""
        default = Physics()
        return {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if getattr(self, f.name) != getattr(default, f.name)
        }


PHYSICS_KEYS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(Physics))
"""The names `[physics]`, `--params` and a grid's `physics` table accept."""


ROBOT_PARTS: tuple[str, ...] = ("physics", "gait", "phases", "mounting")
"""The parts of a robot that can differ from the study's (`Robot.changed`)."""


@dataclass(frozen=True)
class Robot:
    """The robot a walk walks, whole as its robot config describes it (`hardware.config`,
    `RobotConfig.robot`): its physics (frame, motor, floors), its gait (speed and PID),
    each slot's phase offset (the tripods; from the motors' names and `phase_deg`) and each
    slot's spacer layers between the frame and its leg (`[mounting]`; None: chosen for each
    linkage so that neighbouring legs cannot meet, `sim.robot.mounting.auto_spacers`).

    Every command that walks reads all three alike: `hexapod simulate`, `study` and
    `calibrate`, walk maps and walking trials. The defaults are the study's robot.
    """

    physics: Physics = field(default_factory=Physics)
    gait: GaitConfig = field(default_factory=GaitConfig)
    phases_deg: dict[str, float] = field(default_factory=lambda: dict(TRIPOD_OFFSETS_DEG))
    spacers: dict[str, int] | None = None

    def __post_init__(self) -> None:
        if sorted(self.phases_deg) != sorted(LEG_SLOTS):
            raise ValueError(
                f"the robot's legs are named {sorted(self.phases_deg)}; a leg is mounted where "
                f"its motor's name says, so name the six {', '.join(LEG_SLOTS)}"
            )
        for slot, value in self.phases_deg.items():
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"{slot} phase_deg = {value!r}: allowed a number")
            wrong = range_error(
                f"{slot} phase_deg", float(value), limits(0.0, 360.0, open_high=True)
            )
            if wrong:
                raise ValueError(wrong)
        if self.spacers is not None:
            check_spacers(self.spacers)

    def changed(self) -> dict[str, dict[str, float]]:
        """Returns what differs from the study's robot, by part ("physics", "gait",
        "phases", "mounting"; a part with no change left out): what identifies another
        robot, as a walk map's tag and a trial's settings record it."""
        default = GaitConfig()
        parts = {
            "physics": self.physics.changed(),
            "gait": {
                f.name: getattr(self.gait, f.name)
                for f in dataclasses.fields(GaitConfig)
                if getattr(self.gait, f.name) != getattr(default, f.name)
            },
            "phases": {s: v for s, v in self.phases_deg.items() if v != TRIPOD_OFFSETS_DEG[s]},
            "mounting": self.spacers or {},
        }
        return {k: v for k, v in parts.items() if v}

    @classmethod
    def of(cls, changed: dict) -> Robot:
        """Returns the robot `changed` describes (`Robot.changed`'s form).

        Raises:
            ValueError: naming an unknown part, key or a value out of its range.
        """
        unknown = sorted(set(changed) - set(ROBOT_PARTS))
        if unknown:
            raise ValueError(f"robot: unknown part(s) {unknown}; allowed: {', '.join(ROBOT_PARTS)}")
        gait = changed.get("gait", {})
        names = [f.name for f in dataclasses.fields(GaitConfig)]
        if sorted(set(gait) - set(names)):
            raise ValueError(
                f"gait: unknown key(s) {sorted(set(gait) - set(names))}; allowed: {names}"
            )
        for f in dataclasses.fields(GaitConfig):
            if f.name in gait:
                value = gait[f.name]
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise ValueError(f"gait {f.name} = {value!r}: allowed a number")
                wrong = range_error(f.name, float(value), f.metadata)
                if wrong:
                    raise ValueError(f"gait {wrong}")
        return cls(
            physics=Physics.of(changed.get("physics", {})),
            gait=GaitConfig(**{k: float(v) for k, v in gait.items()}),
            phases_deg={**TRIPOD_OFFSETS_DEG, **changed.get("phases", {})},
            spacers=changed.get("mounting") or None,
        )


MAX_SPACERS = 8
"""The most spacer layers a robot config may give a leg (64 mm: with the leg's own layers,
about the longest Technic axle, 12 modules, held in the motor's horn)."""


def check_spacers(spacers: dict) -> None:
    """Raises ValueError unless `spacers` gives each of the six slots a whole number of
    spacer layers from 0 to `MAX_SPACERS` (a robot config's `[mounting]`)."""
    if sorted(spacers) != sorted(LEG_SLOTS):
        raise ValueError(
            f"[mounting] names {sorted(spacers)}; give all six slots ({', '.join(LEG_SLOTS)}) "
            "their spacer layers, or leave the section out to have them chosen for each leg"
        )
    for slot, value in spacers.items():
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_SPACERS:
            raise ValueError(
                f"[mounting] {slot} = {value!r}: allowed a whole number of layers, 0 to "
                f"{MAX_SPACERS}"
            )
