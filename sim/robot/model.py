"""Provides what both MuJoCo models of the robot share: the physics options, floor and frame
(`robot_spec`), where a leg sits (`leg_frame`), its motor (`add_motor`), a beam's body and
mass (`add_beam`), which beams can touch the floor (`floor_reach`), the compiled robot
(`RobotModel`) with its model's loads behind one small interface (`LegLoads`), and one
control tick (`control_tick`) that the walk and the bus emulator's physics both step.

The full model (`sim.robot.full_model`) makes every beam a body; the lean one
(`sim.robot.lean_model`) keeps only the parts that meet the floor. The walk (`sim.robot.walking`)
never asks which it runs: it steps `control_tick` and samples `RobotModel.loads`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import mujoco
import numpy as np

from linkevo.sim.robot.hexapod import (
    BEAM_RADIUS_M,
    LAYER_PITCH_M,
    LEG_SLOTS,
    UNIT_M,
    Floor,
    Frame,
    Motor,
)
from linkevo.sim.robot.leg import Leg

LEG_CONTACT = {"contype": 2, "conaffinity": 1}
"""A beam's contact: it touches the floor, never another beam (beams are on layers)."""
NO_CONTACT = {"contype": 0, "conaffinity": 0}
CONTACT_REACH = 4.0
"""A beam whose lowest point over the turn stays more than this many modules above the
leg's lowest point cannot reach the floor unless the robot tips over: it gets no contact."""
EQUALITY_SOLIMP = [0.999, 0.9999, 0.001, 0.5, 2.0]
"""Near-hard equalities (the lean model's couplings, the full model's loop-closing pins):
a part stays within a fraction of a millimetre of its pose, so a foot stays within 1 mm of
where its linkage puts it (`Walk.foot_deviation_mm`; MuJoCo's default lets a full-model
leg's pins open by a millimetre each, and the foot stray 4-5 mm)."""
BEAM_RGBA = [0.75, 0.75, 0.78, 1]
CRANK_RGBA = [0.85, 0.6, 0.1, 1]


class LegLoads(Protocol):
    """A robot model's legs as the walk sees them: what it re-centres every control tick,
    and the pin loads and loop closures it samples.

    A sample is one row of `width` numbers (the model's own layout); `pin_forces` and
    `loop_errors` turn the samples of a walk into every pin force and every loop-closure
    error over it.
    """

    width: int

    def update(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Runs before each control tick's physics (the lean model re-centres its
        couplings; the full model needs nothing)."""
        ...

    def sample(self, model: mujoco.MjModel, data: mujoco.MjData, out: np.ndarray) -> None:
        """Writes this tick's loads into `out` (width,)."""
        ...

    def pin_forces(self, samples: np.ndarray) -> np.ndarray:
        """Returns every pin force (N) over samples (S, width), flattened."""
        ...

    def loop_errors(self, samples: np.ndarray) -> np.ndarray:
        """Returns every loop-closure error (m) over samples (S, width), flattened."""
        ...


@dataclass(frozen=True)
class RobotModel:
    """A compiled robot and where its parts are.

    Attributes:
        model: the MuJoCo model.
        frame_body: the frame's body id; frame_geom: its box geom id.
        crank_qpos: (6,) qpos address of each leg's crank hinge; crank_dof: (6,) dof address.
        actuators: (6,) each leg's motor actuator id.
        foot_sites: (6,) each leg's foot site id.
        start_phases: (6,) the crank angle (radians) each leg was built at.
        stroke_m: (6,) each leg's stance stroke in metres.
        loads: the model's legs as the walk samples them (`LegLoads`).
        motor: the motor on every crank (`sim.robot.hexapod.Motor`).
        foot_paths: (6, A, 3) each foot's kinematic path over a turn, in the frame's
            coordinates (where the linkage puts the foot at crank angle k 2pi/A).
    """

    model: mujoco.MjModel
    frame_body: int
    frame_geom: int
    crank_qpos: np.ndarray
    crank_dof: np.ndarray
    actuators: np.ndarray
    foot_sites: np.ndarray
    start_phases: np.ndarray
    stroke_m: np.ndarray
    loads: LegLoads
    motor: Motor
    foot_paths: np.ndarray

    def foot_deviation(
        self, phases: np.ndarray, body: np.ndarray, mats: np.ndarray, feet: np.ndarray
    ) -> np.ndarray:
        """Returns (T, 6) each foot's distance (m) from where the linkage puts it at its
        crank's angle, over T ticks.

        Args:
            phases: (T, 6) the cranks' angles (radians, the linkage's frame).
            body: (T, 3) the frame's position; mats: (T, 3, 3) its orientation.
            feet: (T, 6, 3) the foot sites' positions.
        """
        n = self.foot_paths.shape[1]
        u = np.mod(phases / (2 * np.pi) * n, n)  # (T, 6) fractional pose index
        low = np.floor(u).astype(np.int64)
        share = (u - low)[..., None]
        legs = np.arange(6)[None, :]
        local = (1 - share) * self.foot_paths[legs, low % n] + share * self.foot_paths[
            legs, (low + 1) % n
        ]  # (T, 6, 3) in the frame's coordinates
        expected = body[:, None, :] + np.einsum("tij,tkj->tki", mats, local)
        return np.linalg.norm(feet - expected, axis=2)

    def motor_torque(self, data: mujoco.MjData) -> np.ndarray:
        """Returns (6,) each motor's torque on its crank (N·m): the drive less the
        back-EMF."""
        speed = data.qvel[self.crank_dof]
        return data.actuator_force[self.actuators] - self.motor.back_emf_damping * speed

    def at_supply_limit(self, data: mujoco.MjData) -> np.ndarray:
        """Returns (6,) bool: each motor's drive clipped by its supply (on its torque-speed
        line)."""
        drive = np.abs(data.actuator_force[self.actuators])
        return drive >= self.model.actuator_forcerange[self.actuators, 1] * (1 - 1e-3)


def control_tick(robot: RobotModel, data: mujoco.MjData, goal: np.ndarray, steps: int) -> None:
    """One control tick: each motor's speed goal (rad/s, (6,)), the model's per-tick hook,
    then `steps` physics steps (MuJoCo integrates the motors at each, `add_motor`)."""
    data.ctrl[robot.actuators] = goal
    robot.loads.update(robot.model, data)
    mujoco.mj_step(robot.model, data, nstep=steps)


def floor_reach(leg: Leg) -> np.ndarray:
    """(P,) bool: the leg's pieces (`Leg.pieces`) that come within CONTACT_REACH of its
    lowest point."""
    low = leg.piece_ends()[..., 1].min(axis=(1, 2))  # (P,)
    return low <= low.min() + CONTACT_REACH


def check_slots(legs: dict[str, Leg], phases: dict[str, float]) -> None:
    """Raises ValueError naming the slots without a leg or a phase."""
    missing = [s for s in LEG_SLOTS if s not in legs or s not in phases]
    if missing:
        raise ValueError(f"no leg or phase for slot(s) {missing}; every one of {LEG_SLOTS}")


def robot_spec(floor: Floor, frame: Frame, timestep: float, extra_kg: float = 0.0):
    """Returns (spec, frame body): the physics options, the floor and the frame (a free
    box of the frame's mass plus `extra_kg`) that both robot models share."""
    spec = mujoco.MjSpec()
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.solver = mujoco.mjtSolver.mjSOL_NEWTON
    spec.option.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
    # Dense constraint Jacobians: with the sparse ones (MuJoCo's choice from 60 dofs) some
    # study linkages blow up within 10 steps; dense costs nothing measurable here.
    spec.option.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
    _add_scenery(spec)
    spec.worldbody.add_geom(
        name="floor",
        material="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[0, 0, 0.05],
        contype=1,
        conaffinity=1,
        priority=1,
        condim=3,
        friction=[floor.friction, 0.005, 0.0001],
        solref=[max(floor.solref[0], 2 * timestep), floor.solref[1]],
        solimp=[*floor.solimp, 0.5, 2.0],
    )
    body = spec.worldbody.add_body(name="frame")
    body.add_freejoint(name="frame")
    body.add_geom(
        name="frame",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[frame.length / 2, frame.width / 2, frame.height / 2],
        mass=frame.mass_kg + extra_kg,
        rgba=[0.2, 0.25, 0.3, 1],
        **LEG_CONTACT,
    )
    return spec, body


def leg_frame(slot: str, leg: Leg, frame: Frame, spacer: int = 0):
    """Returns a function mapping a linkage point (2,) in modules on a layer to its (3,)
    position in the frame's coordinates: the leg's plane is the frame's side plane, `spacer`
    layers further out (`sim.robot.mounting`), its y axis up, mounted facing the way its
    stance pushes the robot (`Leg.facing`)."""
    side = 1.0 if slot.startswith("left") else -1.0
    along = {"front": 1.0, "middle": 0.0, "rear": -1.0}[slot.split("-")[1]]
    axle = np.array([along * frame.leg_spacing, side * frame.width / 2, 0.0])
    facing = leg.facing()

    def world(node: np.ndarray, layer: int) -> np.ndarray:
        """(..., 2) linkage points in modules -> (..., 3) frame coordinates (m)."""
        lateral = side * (frame.leg_plane + (spacer + layer) * LAYER_PITCH_M)
        node = np.asarray(node, dtype=float) * UNIT_M
        out = np.empty((*node.shape[:-1], 3))
        out[..., 0] = axle[0] + -facing * node[..., 0]
        out[..., 1] = axle[1] + lateral
        out[..., 2] = axle[2] + node[..., 1]
        return out

    return world


def add_beam(
    body,
    origin: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    *,
    mass: float,
    contact: dict,
    rgba: list[float],
) -> None:
    """Adds a beam from `start` to `end` (frame coordinates, (3,)) to `body` (at `origin`)
    as a capsule of the beam's width, or a sphere when its ends meet."""
    geom = {"mass": mass, "size": [BEAM_RADIUS_M, 0, 0], "rgba": rgba, **contact}
    if np.linalg.norm(end - start) > 1e-6:
        body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_CAPSULE, fromto=[*(start - origin), *(end - origin)], **geom
        )
    else:
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, pos=(start - origin).tolist(), **geom)


def add_motor(spec: mujoco.MjSpec, slot: str, motor: Motor) -> None:
    """The slot's motor on its crank hinge (`sim.robot.hexapod.Motor`; control: the speed goal in
    rad/s): its drive as an affine actuator clipped to ± stall (the supply), its back-EMF
    as the hinge's damping and the rotor's inertia as its armature. MuJoCo integrates all
    three at every physics step, implicitly in velocity."""
    spec.add_actuator(
        name=f"{slot}/motor",
        target=f"{slot}/crank",
        trntype=mujoco.mjtTrn.mjTRN_JOINT,
        gaintype=mujoco.mjtGain.mjGAIN_FIXED,
        gainprm=[motor.drive_gain] + [0] * 9,
        biastype=mujoco.mjtBias.mjBIAS_AFFINE,
        biasprm=[0, 0, -motor.drive_bias] + [0] * 7,
        forcelimited=1,
        forcerange=[-motor.stall_nm, motor.stall_nm],
    )
    crank = spec.joint(f"{slot}/crank")
    crank.armature = motor.armature
    crank.damping = [motor.back_emf_damping, 0.0, 0.0]  # linear damping (MuJoCo 4: 3 terms)


def robot_model(
    model: mujoco.MjModel,
    legs: dict[str, Leg],
    phases: dict[str, float],
    loads: LegLoads,
    motor: Motor,
    frame: Frame,
    foot_layers: dict[str, int],
    spacers: dict[str, int],
) -> RobotModel:
    """Returns the compiled model with where its parts are (names as both builders give
    them) and each foot's kinematic path (its leg's foot node on `foot_layers[slot]`, the
    leg `spacers[slot]` layers out)."""

    def ids(kind: mujoco.mjtObj, names: list[str]) -> np.ndarray:
        return np.array([mujoco.mj_name2id(model, kind, n) for n in names], dtype=np.int64)

    cranks = ids(mujoco.mjtObj.mjOBJ_JOINT, [f"{s}/crank" for s in LEG_SLOTS])
    return RobotModel(
        model=model,
        frame_body=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "frame"),
        frame_geom=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "frame"),
        crank_qpos=model.jnt_qposadr[cranks].astype(np.int64),
        crank_dof=model.jnt_dofadr[cranks].astype(np.int64),
        actuators=ids(mujoco.mjtObj.mjOBJ_ACTUATOR, [f"{s}/motor" for s in LEG_SLOTS]),
        foot_sites=ids(mujoco.mjtObj.mjOBJ_SITE, [f"{s}/foot" for s in LEG_SLOTS]),
        start_phases=np.array([phases[s] for s in LEG_SLOTS], dtype=float),
        stroke_m=np.array([legs[s].stance_stroke() * UNIT_M for s in LEG_SLOTS]),
        loads=loads,
        motor=motor,
        foot_paths=np.stack(
            [
                leg_frame(s, legs[s], frame, spacers[s])(legs[s].foot_path(), foot_layers[s])
                for s in LEG_SLOTS
            ]
        ),
    )


def _add_scenery(spec: mujoco.MjSpec) -> None:
    """Light and a chequered floor (10 cm squares), for pictures only."""
    spec.worldbody.add_light(pos=[0, 0, 3], dir=[0, 0, -1], diffuse=[0.7, 0.7, 0.7])
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.add_texture(
        name="floor",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        rgb1=[0.82, 0.82, 0.78],
        rgb2=[0.68, 0.68, 0.64],
        width=200,
        height=200,
    )
    spec.add_material(name="floor", textures=["", "floor"], texrepeat=[5, 5], texuniform=True)
