"""Provides `build_lean_robot`: the hexapod with each leg reduced to what meets the floor.

A leg is a one-degree-of-freedom mechanism: its crank angle fixes every beam. The lean model
keeps the crank (the motor's hinge) and, as bodies, only the rigid parts that can reach the
floor (`sim.robot.model.floor_reach`), each free in the leg's plane (two slides and a hinge)
and tied to the crank by three `joint` equalities: the part's x, z and angle as functions
of the crank angle, taken from the leg's poses (`Leg.paths`). MuJoCo's joint equality is a
quartic in the crank angle, so `Coupling.update` re-centres it on the crank's angle at every
control tick (a least-squares quartic over ±10° of poses, accurate to well under a
micrometre). The other parts carry no load they could not pass on (a LEGO beam weighs grams),
so their mass rides with the frame, and the pins' forces come from the statics of the
massless mechanism (`LegStatics`): the equalities' forces are exactly what the pins exert
on the parts that meet the floor.

The crank's own rigid part (the crank, its extensions and the trusses on it) is such a
coupled body too when it reaches the floor, never beams on the crank's hinge body: MuJoCo
turns a hinge's body by `qpos - qpos0`, and re-centring the couplings moves the crank's
`qpos0` with its angle, so a body on that hinge stays where the crank was at the last
re-centring (a leg whose foot rides on the crank, a "rimless wheel", walked with its feet
still while its couplings held; docs/walking.md, "Where the lean model breaks down").

The coupled parts get an armature (`CONTACT_INERTIA_KG`): MuJoCo's soft contacts scale with
the inertia behind the contact, and without it a few grams of beam sink into a soft floor
far deeper than the crank-driven mechanism would let them (docs/walking.md compares the two
models). It adds no weight; reflected to the crank it is a few percent of the rotor's
inertia over the turn (more at fast-swinging poses), which moves carpet walks by a few
centimetres (`benchmarks/armature_effect.py`, docs/walking.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from linkevo.sim.robot.hexapod import BEAM_RADIUS_M, LEG_SLOTS, UNIT_M, Floor, Frame, Motor
from linkevo.sim.robot.leg import Leg
from linkevo.sim.robot.model import (
    BEAM_RGBA,
    EQUALITY_SOLIMP,
    LEG_CONTACT,
    RobotModel,
    add_beam,
    add_motor,
    check_slots,
    floor_reach,
    leg_frame,
    robot_model,
    robot_spec,
)

LEAN_TIMESTEP_S = 0.002
"""The lean model's physics step: halving it changes walked distances by under 4 %
(docs/walking.md)."""
CONTACT_INERTIA_KG = 0.05
"""Armature of a coupled part's slides (its hinge gets this times (5 cm)²)."""
_DEGREE = 4
_WINDOW = 10  # poses either side of the centre in each quartic fit


def _fit_tables(values: np.ndarray, wind: float) -> np.ndarray:
    """Returns (A, 5) quartic coefficients of a periodic function sampled at A crank angles
    (values (A,); `wind` its increase over one turn), each centred on its own angle."""
    n = len(values)
    step = 2 * np.pi / n
    offsets = np.arange(-_WINDOW, _WINDOW + 1)
    fit = np.linalg.pinv(np.vander(offsets * step, _DEGREE + 1, increasing=True))
    extended = np.concatenate([values[-_WINDOW:] - wind, values, values[:_WINDOW] + wind])
    windows = extended[np.arange(n)[:, None] + np.arange(2 * _WINDOW + 1)[None, :]]
    return windows @ fit.T


@dataclass
class Coupling:
    """The lean model's equalities and how to re-centre them on the cranks' angles.

    Attributes:
        equalities: (C,) equality ids, three per coupled part (x, z, angle), leg by leg.
        leg: (C,) the slot index (0..5) of each.
        tables: (C, A, 5) quartic coefficients per pose (`_fit_tables`).
        wind: (C,) increase of each coupled coordinate over one crank turn.
        start: (C,) each coordinate at the start pose.
        start_pose: (6,) each leg's start pose index.
        scale: (C,) metres per unit of each coordinate's error (1, or a part's reach for
            an angle).
        crank_qpos: (6,) the cranks' qpos addresses.
        statics: each slot's `LegStatics`.
        n_poses: A, the poses per turn.
    """

    equalities: np.ndarray
    leg: np.ndarray
    tables: np.ndarray
    wind: np.ndarray
    start: np.ndarray
    start_pose: np.ndarray
    scale: np.ndarray
    crank_qpos: np.ndarray
    statics: tuple[LegStatics, ...]
    n_poses: int

    @property
    def width(self) -> int:
        """A sample: each leg's pose index (6), then each coupling's force and error (C
        each)."""
        return 6 + 2 * len(self.equalities)

    def sample(self, model: mujoco.MjModel, data: mujoco.MjData, out: np.ndarray) -> None:
        """Writes the legs' poses and the couplings' forces and errors (`width`): the
        equalities' rows come first in the constraint arrays, in id order."""
        n = len(self.equalities)
        out[:6] = self.poses(data)
        out[6 : 6 + n] = data.efc_force[:n]
        out[6 + n :] = np.abs(data.efc_pos[:n]) * self.scale

    def pin_forces(self, samples: np.ndarray) -> np.ndarray:
        """Returns every pin's force at every sample, all legs: the statics of each leg's
        mechanism under its couplings' forces (`LegStatics`)."""
        n = len(self.equalities)
        poses = samples[:, :6].astype(np.int64)  # (S, 6)
        forces = samples[:, 6 : 6 + n]  # (S, C)
        pins = []
        for statics in {id(s): s for s in self.statics}.values():  # legs alike: one solve
            slots = [i for i, s in enumerate(self.statics) if s is statics]
            wrench = np.concatenate(
                [forces[:, self.leg == i].reshape(len(forces), -1, 3) for i in slots]
            )  # (S * slots, K, 3): x, z, angle, in the frame's coordinates
            wrench = wrench * np.array([-statics.leg.facing(), 1.0, 1.0])  # linkage's frame
            pins.append(statics.pin_forces(poses[:, slots].T.ravel(), wrench).ravel())
        return np.concatenate(pins)

    def loop_errors(self, samples: np.ndarray) -> np.ndarray:
        """Returns every coupling's error (m) at every sample."""
        n = len(self.equalities)
        return samples[:, 6 + n :].ravel()

    def poses(self, data: mujoco.MjData) -> np.ndarray:
        """Returns (6,) int each leg's nearest pose index (unwrapped: may exceed A)."""
        step = 2 * np.pi / self.n_poses
        return self.start_pose + np.rint(data.qpos[self.crank_qpos] / step).astype(np.int64)

    def update(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Re-centres every coupling on the pose nearest its crank's angle: the crank's
        reference angle (`qpos0`) moves there and the quartic is the one fitted there."""
        n = self.n_poses
        pose = self.poses(data)
        model.qpos0[self.crank_qpos] = (pose - self.start_pose) * (2 * np.pi / n)
        k, turns = pose % n, pose // n
        coefficients = self.tables[np.arange(len(self.leg)), k[self.leg]]
        coefficients[:, 0] += self.wind * turns[self.leg] - self.start
        model.eq_data[self.equalities, :5] = coefficients


@dataclass(frozen=True)
class LegStatics:
    """The statics of one massless leg: the pin forces that balance given wrenches on its
    coupled parts, with the motor's torque on the crank.

    Pins: at every node where several rigid parts (or a part and the frame) meet, one pin
    joins each part to the node's first owner (the frame where it is one), as the full
    model's hinges and loop closures do.

    Attributes:
        leg: the leg.
        pins: (J, 3) int node, owner part, other part (-1 is the frame).
        pivots: (P,) each moving part's pivot node (where a coupled part's body sits).
        coupled: (K,) the coupled parts, in the order of their equalities.
    """

    leg: Leg
    pins: np.ndarray
    pivots: np.ndarray
    coupled: np.ndarray
    _inverses: dict[int, np.ndarray] = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def of(cls, leg: Leg, coupled: list[int]) -> LegStatics:
        owners: dict[int, list[int]] = {}
        for b, (start, end) in enumerate(leg.beams):
            for node in (int(start), int(end)):
                part = int(leg.part[b])
                if part not in owners.setdefault(node, []):
                    owners[node].append(part)
        for node in leg.frame_nodes:
            owners.setdefault(int(node), [])
            if -1 not in owners[int(node)]:
                owners[int(node)].append(-1)
        pins = []
        for node, parts in owners.items():
            hub = -1 if -1 in parts else parts[0]
            pins += [(node, hub, p) for p in parts if p != hub]
        pivots = np.array(
            [int(leg.beams[np.flatnonzero(leg.part == p)[0], 0]) for p in range(leg.n_parts)]
        )
        return cls(leg, np.array(pins, dtype=np.int64).reshape(-1, 3), pivots, np.array(coupled))

    def solve(self, poses: np.ndarray, wrenches: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Returns (S, J, 2) each pin's force (N, on its part from the node's owner, in the
        linkage's frame) and (S,) the motor's torque (N·m, counter-clockwise) that balance
        the wrenches (least squares where the pins are redundant).

        Args:
            poses: (S,) pose indices (modulo A).
            wrenches: (S, K, 3) the force (x, y, in the linkage's frame) and moment (about
                the part's pivot, counter-clockwise) the pins exert on each coupled part.
        """
        n_parts = self.leg.n_parts
        unique, index = np.unique(poses % self.leg.paths.shape[1], return_inverse=True)
        missing = [int(u) for u in unique if int(u) not in self._inverses]
        if missing:  # each pose's system is inverted once per leg
            for pose, inverse in zip(missing, np.linalg.pinv(self._systems(missing)), strict=True):
                self._inverses[pose] = inverse
        inverses = np.stack([self._inverses[int(u)] for u in unique])
        loads = np.zeros((len(poses), 3 * n_parts))
        for k, part in enumerate(self.coupled):
            loads[:, 3 * part : 3 * part + 3] = wrenches[:, k]
        unknowns = np.einsum("sij,sj->si", inverses[index], loads)
        return unknowns[:, :-1].reshape(len(poses), len(self.pins), 2), unknowns[:, -1]

    def _systems(self, poses: list[int]) -> np.ndarray:
        """Returns (U, 3P, 2J + 1) the balance of every moving part (force x, y, moment)
        in the pins' forces and the motor's torque, at each pose."""
        n_parts, n_pins = self.leg.n_parts, len(self.pins)
        nodes = self.leg.paths[:, poses] * UNIT_M  # (M, U, 2)
        system = np.zeros((len(poses), 3 * n_parts, 2 * n_pins + 1))
        for j, (node, hub, other) in enumerate(self.pins):
            for part, sign in ((other, 1.0), (hub, -1.0)):
                if part < 0:
                    continue
                arm = nodes[node] - nodes[self.pivots[part]]  # (U, 2)
                system[:, 3 * part, 2 * j] = sign
                system[:, 3 * part + 1, 2 * j + 1] = sign
                system[:, 3 * part + 2, 2 * j] = -sign * arm[:, 1]
                system[:, 3 * part + 2, 2 * j + 1] = sign * arm[:, 0]
        system[:, 2, -1] = 1.0  # the motor's torque on the crank (part 0)
        return system

    def pin_forces(self, poses: np.ndarray, wrenches: np.ndarray) -> np.ndarray:
        """Returns (S, J) each pin's force magnitude (N); arguments as `solve`."""
        return np.linalg.norm(self.solve(poses, wrenches)[0], axis=2)


def build_lean_robot(
    legs: dict[str, Leg],
    phases: dict[str, float],
    floor: Floor,
    *,
    frame: Frame | None = None,
    motor: Motor | None = None,
    timestep: float = LEAN_TIMESTEP_S,
    drop: float = 0.002,
    spacers: dict[str, int] | None = None,
) -> RobotModel:
    """Returns the lean robot standing just above the floor; arguments as
    `sim.robot.full_model.build_robot`. Its `loads` (a `Coupling`) hold the equalities to
    re-centre and the pin statics of each slot."""
    frame = frame or Frame()
    motor = motor or Motor()
    check_slots(legs, phases)
    spacers = spacers or dict.fromkeys(LEG_SLOTS, 0)
    reach = {s: floor_reach(legs[s]) for s in LEG_SLOTS}  # per piece
    coupled = {s: [int(p) for p in np.unique(legs[s].piece_part[reach[s]])] for s in LEG_SLOTS}
    carried = sum(
        float(legs[s].piece_kg[~np.isin(legs[s].piece_part, coupled[s])].sum()) for s in LEG_SLOTS
    )
    spec, body = robot_spec(floor, frame, timestep, extra_kg=carried)
    rows: list[_Row] = []
    foot_layers: dict[str, int] = {}
    lowest = -frame.height / 2
    for i, slot in enumerate(LEG_SLOTS):
        leg, world = legs[slot], leg_frame(slot, legs[slot], frame, spacers[slot])
        pose = leg.pose_index(phases[slot])
        nodes = leg.paths[:, pose]
        ends = leg.piece_ends(np.array([pose]))[:, 0]  # (P, 2, 2)
        axle = world(nodes[0], 0)
        crank = body.add_body(name=f"{slot}/crank", pos=axle.tolist())
        crank.add_joint(
            name=f"{slot}/crank", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, leg.facing(), 0]
        )
        crank.add_geom(
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[0.005, 0, 0],
            mass=0.002,
            contype=0,
            conaffinity=0,
            rgba=[0.85, 0.6, 0.1, 1],
        )
        sites = {}  # part -> (body, its origin in the frame's coordinates)
        for part in coupled[slot]:
            members = np.flatnonzero(leg.part == part)
            pivot = int(leg.beams[members[0], 0])
            if part == -1:
                target, origin = body, np.zeros(3)
            else:  # the crank's own part too: its hinge's body turns by qpos - qpos0
                origin = world(nodes[pivot], int(leg.layer[members[0]]))
                target = body.add_body(name=f"{slot}/part{part}", pos=origin.tolist())
                rows += _couple(spec, target, slot, i, leg, part, pivot, pose)
            sites[part] = (target, origin)
            for k in np.flatnonzero((leg.piece_part == part) & reach[slot]):
                lowest = min(lowest, _add_piece(target, origin, world, leg, ends, int(k)))
        held = [
            b
            for b in range(len(leg.beams))
            if leg.foot in leg.beams[b] and int(leg.part[b]) in coupled[slot]
        ]
        if held:
            owner, origin = sites[int(leg.part[held[0]])]
            foot_layers[slot] = int(leg.layer[held[0]])
        else:  # the lowest point is a bare frame hole: the foot is the frame's, as in full
            owner, origin = body, np.zeros(3)
            foot_layers[slot] = 0
        foot = world(nodes[leg.foot], foot_layers[slot])
        owner.add_site(name=f"{slot}/foot", pos=(foot - origin).tolist(), size=[0.004, 0, 0])
        add_motor(spec, slot, motor)
    body.pos = [0.0, 0.0, -(lowest - BEAM_RADIUS_M) + drop]
    model = spec.compile()
    names = [r.name for r in rows]
    statics = {  # one per distinct leg: slots with the same leg share its statics
        id(legs[s]): LegStatics.of(legs[s], [p for p in coupled[s] if p >= 0]) for s in LEG_SLOTS
    }
    cranks = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"{s}/crank") for s in LEG_SLOTS]
    coupling = Coupling(
        equalities=np.array(
            [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, n) for n in names],
            dtype=np.int64,
        ),
        leg=np.array([r.leg for r in rows], dtype=np.int64),
        tables=np.stack([r.table for r in rows]) if rows else np.zeros((0, 1, 5)),
        wind=np.array([r.wind for r in rows]),
        start=np.array([r.start for r in rows]),
        start_pose=np.array([legs[s].pose_index(phases[s]) for s in LEG_SLOTS]),
        scale=np.array([r.scale for r in rows]),
        crank_qpos=np.array([model.jnt_qposadr[j] for j in cranks], dtype=np.int64),
        statics=tuple(statics[id(legs[s])] for s in LEG_SLOTS),
        n_poses=legs[LEG_SLOTS[0]].paths.shape[1],
    )
    return robot_model(model, legs, phases, coupling, motor, frame, foot_layers, spacers)


@dataclass(frozen=True)
class _Row:
    """One coupled coordinate before compiling: its equality's name, slot index, quartic
    tables, wind over a turn, start value and metres per unit."""

    name: str
    leg: int
    table: np.ndarray
    wind: float
    start: float
    scale: float


def _add_piece(target, origin, world, leg: Leg, ends: np.ndarray, k: int) -> float:
    """Adds piece k (`Leg.pieces`, its ends (P, 2, 2) at the build's pose) to a body as a
    beam that touches the floor; returns its lowest centre-line height in the frame's
    coordinates."""
    layer = int(leg.piece_layer[k])
    start, end = world(ends[k, 0], layer), world(ends[k, 1], layer)
    mass = float(leg.piece_kg[k])
    add_beam(target, origin, start, end, mass=mass, contact=LEG_CONTACT, rgba=BEAM_RGBA)
    return float(min(start[2], end[2]))


def _couple(spec, target, slot: str, i: int, leg: Leg, part: int, pivot: int, pose: int):
    """Gives a part's body its planar freedom (slides along the frame's x and z, a hinge
    about the leg's axis) and ties each to the crank; returns the three `_Row`s."""
    facing = leg.facing()
    members = np.flatnonzero(leg.part == part)
    nodes = sorted({int(n) for b in members for n in leg.beams[b]} - {pivot})
    arms = [np.linalg.norm(leg.paths[n] - leg.paths[pivot], axis=1) for n in nodes]
    other = nodes[int(np.argmax([a.min() for a in arms]))]
    reach_m = float(max(a.max() for a in arms)) * UNIT_M
    pivot_path = leg.paths[pivot] * UNIT_M  # (A, 2)
    arm = leg.paths[other] - leg.paths[pivot]
    angle = np.unwrap(np.arctan2(arm[:, 1], arm[:, 0]))
    last_step = np.angle(np.exp(1j * (angle[0] - angle[-1])))  # pose A-1 to pose 0
    wind = 2 * np.pi * round((angle[-1] + last_step - angle[0]) / (2 * np.pi))
    name = target.name
    armature = {"x": CONTACT_INERTIA_KG, "z": CONTACT_INERTIA_KG, "a": CONTACT_INERTIA_KG * 0.05**2}
    rows = []
    for coord, axis, values, turn, scale in (
        ("x", [1, 0, 0], -facing * pivot_path[:, 0], 0.0, 1.0),
        ("z", [0, 0, 1], pivot_path[:, 1], 0.0, 1.0),
        ("a", [0, facing, 0], angle, wind, reach_m),
    ):
        kind = mujoco.mjtJoint.mjJNT_HINGE if coord == "a" else mujoco.mjtJoint.mjJNT_SLIDE
        target.add_joint(name=f"{name}/{coord}", type=kind, axis=axis, armature=armature[coord])
        spec.add_equality(
            name=f"{name}/{coord}",
            type=mujoco.mjtEq.mjEQ_JOINT,
            objtype=mujoco.mjtObj.mjOBJ_JOINT,
            name1=f"{name}/{coord}",
            name2=f"{slot}/crank",
            data=[0.0] * 12,
            solref=[2 * spec.option.timestep, 1.0],
            solimp=EQUALITY_SOLIMP,
        )
        rows.append(
            _Row(f"{name}/{coord}", i, _fit_tables(values, turn), turn, float(values[pose]), scale)
        )
    return rows
