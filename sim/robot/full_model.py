"""Provides `build_robot`: the hexapod with six linkage legs as a MuJoCo model, built with
`mujoco.MjSpec`, every beam a body (the full model; `sim.robot.lean_model` has the lean one,
`sim.robot.model` what both share).

Each leg is a kinematic tree: one body per rigid part (a beam, or a beam and its
extensions), a hinge per pin, the crank's hinge driven by the leg's motor; every other pin
closes a loop as one `connect` equality placed at the assembled pose, so the loops start
closed. The linkage's plane is the robot's side plane, its y axis up, mounted facing the
way its stance pushes the robot (`Leg.facing`: a builder turns a leg round that would walk
the robot backwards), and each beam sits `layer` pitches outside the frame, beyond its
slot's spacers (`sim.robot.mounting`). A right-side leg is the mirror image of a left-side
one, so in its own frame every leg turns the same way. Only beams and the frame touch the
floor; beams pass through each other (they are on layers; legs that meet on a shared layer
are caught by `sim.robot.mounting.strikes`).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from linkevo.sim.robot.hexapod import BEAM_RADIUS_M, LEG_SLOTS, Floor, Frame, Motor
from linkevo.sim.robot.leg import Leg
from linkevo.sim.robot.model import (
    BEAM_RGBA,
    CRANK_RGBA,
    EQUALITY_SOLIMP,
    LEG_CONTACT,
    NO_CONTACT,
    RobotModel,
    add_beam,
    add_motor,
    check_slots,
    floor_reach,
    leg_frame,
    robot_model,
    robot_spec,
)

TIMESTEP_S = 0.001
"""Physics step. At 1 ms walked distances agree with 0.5 ms within 1 %; at 2 ms they drift
by a few percent (a flat stance then beats its no-slip bound) and loops open by up to 3 mm
(docs/walking.md). Equality and contact time constants are twice the step or more."""
PIN_DAMPING = 1e-4
"""Viscous friction of a LEGO pin, N·m per rad/s (an estimate; it only damps rattling)."""
_HINGE = mujoco.mjtJoint.mjJNT_HINGE


@dataclass(frozen=True)
class RigidLoads:
    """The full model's loads (`sim.robot.model.LegLoads`): each tree pin's force (its
    part's interaction force with its parent, N) and each loop-closing pin's force and gap.

    Attributes:
        leg_bodies: (K,) every leg part's body id (its tree pin is its hinge to its parent).
        n_loops: the connect equalities, one per loop-closing pin (their constraint rows
            come first, three each).
    """

    leg_bodies: np.ndarray
    n_loops: int

    @property
    def width(self) -> int:
        return len(self.leg_bodies) + 2 * self.n_loops

    def update(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        return None

    def sample(self, model: mujoco.MjModel, data: mujoco.MjData, out: np.ndarray) -> None:
        mujoco.mj_rnePostConstraint(model, data)
        k, rows = len(self.leg_bodies), 3 * self.n_loops
        out[:k] = np.linalg.norm(data.cfrc_int[self.leg_bodies, 3:], axis=1)
        out[k : k + self.n_loops] = np.linalg.norm(data.efc_force[:rows].reshape(-1, 3), axis=1)
        out[k + self.n_loops :] = np.linalg.norm(data.efc_pos[:rows].reshape(-1, 3), axis=1)

    def pin_forces(self, samples: np.ndarray) -> np.ndarray:
        return samples[:, : len(self.leg_bodies) + self.n_loops].ravel()

    def loop_errors(self, samples: np.ndarray) -> np.ndarray:
        return samples[:, len(self.leg_bodies) + self.n_loops :].ravel()


def build_robot(
    legs: dict[str, Leg],
    phases: dict[str, float],
    floor: Floor,
    *,
    frame: Frame | None = None,
    motor: Motor | None = None,
    timestep: float = TIMESTEP_S,
    drop: float = 0.002,
    spacers: dict[str, int] | None = None,
) -> RobotModel:
    """Returns the compiled robot standing just above the floor.

    Args:
        legs: the leg mounted in each of the six slots (`sim.robot.hexapod.LEG_SLOTS`).
        phases: each slot's crank angle at the start, radians (its pose is built there).
        floor: the floor's contact.
        frame, motor: the chassis and motor (defaults: the study's robot).
        spacers: each slot's spacer layers between the frame and the leg
            (`sim.robot.mounting`; default none).
        timestep: physics step in seconds.
        drop: gap between the lowest point and the floor at the start, metres.
    """
    frame = frame or Frame()
    motor = motor or Motor()
    check_slots(legs, phases)
    spacers = spacers or dict.fromkeys(LEG_SLOTS, 0)
    spec, body = robot_spec(floor, frame, timestep)
    builders = [
        _LegBuilder(spec, body, s, legs[s], phases[s], frame, spacers[s], timestep)
        for s in LEG_SLOTS
    ]
    for slot in LEG_SLOTS:
        add_motor(spec, slot, motor)
    lowest = min(leg.lowest for leg in builders)
    lowest = min(lowest, -frame.height / 2)
    body.pos = [0.0, 0.0, -lowest + drop]
    model = spec.compile()
    bodies = [n for b in builders for n in b.body_names]
    loads = RigidLoads(
        leg_bodies=np.array(
            [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n) for n in bodies],
            dtype=np.int64,
        ),
        n_loops=sum(len(b.pin_names) for b in builders),
    )
    foot_layers = {b.slot: b.foot_layer for b in builders}
    return robot_model(model, legs, phases, loads, motor, frame, foot_layers, spacers)


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
        spacer: int,
        timestep: float,
    ) -> None:
        self.slot = slot
        self._timestep = timestep
        self._world = leg_frame(slot, leg, frame, spacer)
        self._facing = leg.facing()
        nodes = leg.pose(phase)  # (M, 2) modules
        self.body_names: list[str] = []
        self.pin_names: list[str] = []
        owner: dict[int, tuple[object, np.ndarray, int]] = {}  # node -> (body, origin, layer)
        for node in leg.frame_nodes:
            owner[int(node)] = (frame_body, np.zeros(3), 0)
        self._reach = floor_reach(leg)
        self._ends = leg.piece_ends(np.array([leg.pose_index(phase)]))[:, 0]  # (P, 2, 2)
        self.lowest = np.inf
        for k in np.flatnonzero(leg.piece_part == -1):  # pieces fixed to the frame
            self._add_piece(frame_body, np.zeros(3), leg, k, crank=False)
        for b in np.flatnonzero(leg.part == -1):
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
            for k in np.flatnonzero(leg.piece_part == part):
                self._add_piece(child, origin, leg, k, crank=is_crank)
            pinned = {pivot}  # one pin per node of the part: a second would be redundant
            for b in members:
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
        self.foot_layer = foot_layer
        foot_body.add_site(
            name=f"{slot}/foot",
            pos=(self._world(nodes[leg.foot], foot_layer) - foot_origin).tolist(),
            size=[0.004, 0, 0],
        )

    def _add_piece(self, body, origin, leg: Leg, k: int, crank: bool) -> None:
        """Adds piece k (`Leg.pieces`) on its layer; it touches the floor only if some crank
        angle brings it within reach (`floor_reach`)."""
        layer = int(leg.piece_layer[k])
        start = self._world(self._ends[k, 0], layer)
        end = self._world(self._ends[k, 1], layer)
        add_beam(
            body,
            origin,
            start,
            end,
            mass=float(leg.piece_kg[k]),
            contact=LEG_CONTACT if self._reach[k] else NO_CONTACT,
            rgba=CRANK_RGBA if crank else BEAM_RGBA,
        )
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
            solimp=EQUALITY_SOLIMP,
        )
        self.pin_names.append(name)
