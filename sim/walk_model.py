"""Provides `build_robot`: the hexapod with six linkage legs as a MuJoCo model, built with
`mujoco.MjSpec`, every beam a body (the full model; `sim.lean_model` has the lean one),
and what both models share: the physics options, floor and frame (`robot_spec`), where a
leg sits (`leg_frame`), its motor (`add_motor`) and which beams can touch the floor
(`floor_reach`).

Each leg is a kinematic tree: one body per rigid part (a beam, or a beam and its
extensions), a hinge per pin, the crank's hinge driven by the leg's motor; every other pin
closes a loop as one `connect` equality placed at the assembled pose, so the loops start
closed. The linkage's plane is the robot's side plane, its y axis up, mounted facing the
way its stance pushes the robot (`Leg.facing`: a builder turns a leg round that would walk
the robot backwards), and each beam sits `layer` pitches outside the frame. A right-side
leg is the mirror image of a left-side one, so in its own frame every leg turns the same
way. Only beams and the frame touch the floor; beams pass through each other (they are on
layers).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from linkevo.sim.leg import Leg
from linkevo.sim.robot import (
    BEAM_KG_PER_MODULE,
    BEAM_RADIUS_M,
    LAYER_PITCH_M,
    LEG_SLOTS,
    UNIT_M,
    Floor,
    Frame,
    Motor,
)

TIMESTEP_S = 0.001
"""Physics step. At 1 ms walked distances agree with 0.5 ms within 1 %; at 2 ms they drift
by a few percent (a flat stance then beats its no-slip bound) and loops open by up to 3 mm
(docs/walking.md). Equality and contact time constants are twice the step or more."""
PIN_DAMPING = 1e-4
"""Viscous friction of a LEGO pin, N·m per rad/s (an estimate; it only damps rattling)."""
_HINGE = mujoco.mjtJoint.mjJNT_HINGE
LEG_CONTACT = {"contype": 2, "conaffinity": 1}  # touches the floor, never another beam
CONTACT_REACH = 4.0
"""A beam whose lowest point over the turn stays more than this many modules above the
leg's lowest point cannot reach the floor unless the robot tips over: it gets no contact."""


def floor_reach(leg: Leg) -> np.ndarray:
    """(B,) bool: the beams that come within CONTACT_REACH of the leg's lowest point."""
    heights = leg.paths[leg.beams, :, 1]  # (B, 2, A)
    low = heights.min(axis=(1, 2))
    return low <= low.min() + CONTACT_REACH


@dataclass(frozen=True)
class RobotModel:
    """A compiled robot and where its parts are.

    Attributes:
        model: the MuJoCo model.
        frame_body: the frame's body id; frame_geom: its box geom id.
        crank_qpos: (6,) qpos address of each leg's crank hinge; crank_dof: (6,) dof address.
        actuators: (6,) each leg's motor actuator id.
        foot_sites: (6,) each leg's foot site id.
        leg_bodies: (K,) every leg part's body id (its tree pin is its hinge to its parent).
        loop_pins: (L,) the connect equalities, one per loop-closing pin.
        start_phases: (6,) the crank angle (radians) each leg was built at.
        stroke_m: (6,) each leg's stance stroke in metres.
        coupling: the lean model's `sim.lean_model.Coupling` (None for the full model).
    """

    model: mujoco.MjModel
    frame_body: int
    frame_geom: int
    crank_qpos: np.ndarray
    crank_dof: np.ndarray
    actuators: np.ndarray
    foot_sites: np.ndarray
    leg_bodies: np.ndarray
    loop_pins: np.ndarray
    start_phases: np.ndarray
    stroke_m: np.ndarray
    coupling: object | None = None


def build_robot(
    legs: dict[str, Leg],
    phases: dict[str, float],
    floor: Floor,
    *,
    frame: Frame | None = None,
    motor: Motor | None = None,
    timestep: float = TIMESTEP_S,
    drop: float = 0.002,
) -> RobotModel:
    """Returns the compiled robot standing just above the floor.

    Args:
        legs: the leg mounted in each of the six slots (`sim.robot.LEG_SLOTS`).
        phases: each slot's crank angle at the start, radians (its pose is built there).
        floor: the floor's contact.
        frame, motor: the chassis and motor (defaults: the study's robot).
        timestep: physics step in seconds.
        drop: gap between the lowest point and the floor at the start, metres.
    """
    frame = frame or Frame()
    motor = motor or Motor()
    check_slots(legs, phases)
    spec, body = robot_spec(floor, frame, timestep)
    builders = [_LegBuilder(spec, body, s, legs[s], phases[s], frame, timestep) for s in LEG_SLOTS]
    for slot in LEG_SLOTS:
        add_motor(spec, slot, motor)
    lowest = min(leg.lowest for leg in builders)
    lowest = min(lowest, -frame.height / 2)
    body.pos = [0.0, 0.0, -lowest + drop]
    model = spec.compile()
    return robot_model(
        model,
        legs,
        phases,
        leg_bodies=[n for b in builders for n in b.body_names],
        loop_pins=[n for b in builders for n in b.pin_names],
    )


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


def leg_frame(slot: str, leg: Leg, frame: Frame):
    """Returns a function mapping a linkage point (2,) in modules on a layer to its (3,)
    position in the frame's coordinates: the leg's plane is the frame's side plane, its
    y axis up, mounted facing the way its stance pushes the robot (`Leg.facing`)."""
    side = 1.0 if slot.startswith("left") else -1.0
    along = {"front": 1.0, "middle": 0.0, "rear": -1.0}[slot.split("-")[1]]
    axle = np.array([along * frame.leg_spacing, side * frame.width / 2, 0.0])
    facing = leg.facing()

    def world(node: np.ndarray, layer: int) -> np.ndarray:
        lateral = side * (frame.leg_plane + layer * LAYER_PITCH_M)
        x, y = np.asarray(node) * UNIT_M
        return axle + np.array([-facing * x, lateral, y])

    return world


def add_motor(spec: mujoco.MjSpec, slot: str, motor: Motor) -> None:
    """The slot's motor on its crank hinge: the velocity servo of `Motor` (control: the
    speed goal in rad/s; the walk sets its force range to `Motor.torque_limits` every
    control tick) and the rotor's inertia as the hinge's armature."""
    gain = motor.servo_gain
    spec.add_actuator(
        name=f"{slot}/motor",
        target=f"{slot}/crank",
        trntype=mujoco.mjtTrn.mjTRN_JOINT,
        gaintype=mujoco.mjtGain.mjGAIN_FIXED,
        gainprm=[gain] + [0] * 9,
        biastype=mujoco.mjtBias.mjBIAS_AFFINE,
        biasprm=[0, 0, -gain] + [0] * 7,
        forcelimited=1,
        forcerange=[-motor.stall_nm, motor.stall_nm],
    )
    spec.joint(f"{slot}/crank").armature = motor.armature


def robot_model(
    model: mujoco.MjModel,
    legs: dict[str, Leg],
    phases: dict[str, float],
    *,
    leg_bodies: list[str],
    loop_pins: list[str] = (),
    coupling: object | None = None,
) -> RobotModel:
    """Returns the compiled model with where its parts are (names as both builders give
    them)."""

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
        leg_bodies=ids(mujoco.mjtObj.mjOBJ_BODY, leg_bodies),
        loop_pins=ids(mujoco.mjtObj.mjOBJ_EQUALITY, list(loop_pins)),
        start_phases=np.array([phases[s] for s in LEG_SLOTS], dtype=float),
        stroke_m=np.array([legs[s].stance_stroke() * UNIT_M for s in LEG_SLOTS]),
        coupling=coupling,
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


class _LegBuilder:
    """Adds one leg's bodies, hinges, loop closures and foot site to the frame."""

    def __init__(
        self,
        spec: mujoco.MjSpec,
        frame_body,
        slot: str,
        leg: Leg,
        phase: float,
        frame: Frame,
        timestep: float,
    ) -> None:
        self.slot = slot
        self._timestep = timestep
        self._world = leg_frame(slot, leg, frame)
        self._facing = leg.facing()
        nodes = leg.pose(phase)  # (M, 2) modules
        self.body_names: list[str] = []
        self.pin_names: list[str] = []
        owner: dict[int, tuple[object, np.ndarray, int]] = {}  # node -> (body, origin, layer)
        for node in leg.frame_nodes:
            owner[int(node)] = (frame_body, np.zeros(3), 0)
        self._reach = floor_reach(leg)
        self.lowest = np.inf
        for b in np.flatnonzero(leg.part == -1):  # beams fixed to the frame
            self._add_beam(frame_body, np.zeros(3), leg, nodes, b, crank=False)
            for node in leg.beams[b]:
                owner.setdefault(int(node), (frame_body, np.zeros(3), int(leg.layer[b])))
        for part in range(leg.n_parts):
            members = np.flatnonzero(leg.part == part)
            first = members[0]
            pivot = int(leg.beams[first, 0])
            parent, parent_origin, _ = owner[pivot]
            origin = self._world(nodes[pivot], int(leg.layer[first]))
            name = f"{slot}/part{part}"
            child = parent.add_body(name=name, pos=(origin - parent_origin).tolist())
            self.body_names.append(name)
            is_crank = part == 0
            child.add_joint(
                name=f"{slot}/crank" if is_crank else f"{slot}/pin{part}",
                type=_HINGE,
                axis=[0, self._facing, 0],  # counter-clockwise in the linkage's frame
                damping=0.0 if is_crank else PIN_DAMPING,
            )
            pinned = {pivot}  # one pin per node of the part: a second would be redundant
            for b in members:
                self._add_beam(child, origin, leg, nodes, b, crank=is_crank)
                for node in (int(leg.beams[b, 0]), int(leg.beams[b, 1])):
                    if node in pinned:
                        continue
                    pinned.add(node)
                    if node not in owner:
                        owner[node] = (child, origin, int(leg.layer[b]))
                    elif owner[node][0] is not child:
                        self._close_loop(spec, child, origin, owner[node], nodes[node], b, leg)
        self.lowest -= BEAM_RADIUS_M
        foot_body, foot_origin, foot_layer = owner[leg.foot]
        foot_body.add_site(
            name=f"{slot}/foot",
            pos=(self._world(nodes[leg.foot], foot_layer) - foot_origin).tolist(),
            size=[0.004, 0, 0],
        )

    def _add_beam(self, body, origin, leg: Leg, nodes: np.ndarray, b: int, crank: bool) -> None:
        """Adds beam b as a capsule (a sphere when its ends meet) on its layer; it touches
        the floor only if some crank angle brings it within reach (`_floor_reach`)."""
        layer = int(leg.layer[b])
        start = self._world(nodes[leg.beams[b, 0]], layer)
        end = self._world(nodes[leg.beams[b, 1]], layer)
        length = float(np.linalg.norm(end - start))
        contact = LEG_CONTACT if self._reach[b] else {"contype": 0, "conaffinity": 0}
        geom = {
            "mass": max(length / UNIT_M, 0.5) * BEAM_KG_PER_MODULE,
            "rgba": [0.85, 0.6, 0.1, 1] if crank else [0.75, 0.75, 0.78, 1],
            "size": [BEAM_RADIUS_M, 0, 0],
            **contact,
        }
        if length > 1e-6:
            body.add_geom(
                type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                fromto=[*(start - origin), *(end - origin)],
                **geom,
            )
        else:
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, pos=(start - origin).tolist(), **geom)
        self.lowest = min(self.lowest, start[2], end[2])

    def _close_loop(self, spec, child, origin, other, node_xy, beam, leg) -> None:
        """Adds the pin joining this part to the body that owns the node, as a connect
        equality anchored at the node (in this part's frame)."""
        other_body, _, _ = other
        name = f"{self.slot}/loop{len(self.pin_names)}"
        anchor = self._world(node_xy, int(leg.layer[beam])) - origin
        spec.add_equality(
            name=name,
            type=mujoco.mjtEq.mjEQ_CONNECT,
            objtype=mujoco.mjtObj.mjOBJ_BODY,
            name1=child.name,
            name2=other_body.name,
            data=[*anchor] + [0.0] * 9,
            solref=[2 * self._timestep, 1.0],
        )
        self.pin_names.append(name)
