"""Provides `Leg`: one linkage as the 3-D robot carries it (its LEGO build of real Technic
parts where one exists, else the linkage as evolved), with the node paths over a fine crank
turn, the rigid parts, the layer of every beam and the physical beams it is built from."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from linkevo.sim.errors import LinkevoError
from linkevo.sim.linkage.decoding import NODE_KINDS, LinkageBatch, decode
from linkevo.sim.linkage.kinematics import simulate
from linkevo.sim.robot.hexapod import BEAM_KG_PER_MODULE, MAX_SPACERS, UNIT_M
from linkevo.sim.robot.layers import LayerError, layer_plan
from linkevo.sim.robot.lego import QuantiseError, whole_module_build
from linkevo.sim.robot.parts import PartsBuild, PartsError, assign_parts
from linkevo.sim.study import DEFAULT_ANGLES

POSE_ANGLES = 360
"""Crank angles per turn at which a leg's poses are known (one degree apart)."""


class LegError(LinkevoError, ValueError):
    """A linkage that cannot be walked (it does not turn a full turn); says why."""


@dataclass(frozen=True)
class Leg:
    """One leg linkage in modules, in its own frame (x, y; the crank turns counter-clockwise
    about node 0, the motor).

    Attributes:
        paths: (M, A, 2) float64 every node's position at crank angles k*2*pi/A.
        beams: (B, 2) int64 each beam's start and end node.
        part: (B,) int64 the rigid part of each beam (`rigid_parts`): -1 for beams fixed
            to the frame, else numbered from 0 in beam order; beam 0 (the crank) is in
            part 0.
        layer: (B,) int64 each beam's layer, 0 nearest the frame.
        frame_nodes: (F,) int64 nodes fixed to the frame, the motor (node 0) first.
        foot: the foot node (lowest over the turn).
        built: True for the LEGO build (whole-module beams of real parts), False for the
            linkage as evolved (no whole-module rounding of it turns, or no real parts
            build it).
        note: why the leg is as evolved, or "" for a LEGO build.
        pieces: (P,) int64 the physical beams' linkage beams: each lies along one (its
            bar's first beam) and moves with that beam's part (`sim.robot.parts.Piece`);
            as evolved, one per beam.
        piece_span: (P, 2) float64 each piece's end holes, modules along its beam from the
            beam's start node.
        piece_layer: (P,) int64 each piece's layer.
        piece_kg: (P,) float64 each piece's mass.
        most_spacers: the most spacer layers it can be mounted on (`sim.robot.mounting`):
            its frame axles, lengthened through them, stay within the longest Technic
            axle; as evolved, `MAX_SPACERS`.
    """

    paths: np.ndarray
    beams: np.ndarray
    part: np.ndarray
    layer: np.ndarray
    frame_nodes: np.ndarray
    foot: int
    built: bool
    note: str = ""
    pieces: np.ndarray | None = None
    piece_span: np.ndarray | None = None
    piece_layer: np.ndarray | None = None
    piece_kg: np.ndarray | None = None
    most_spacers: int = MAX_SPACERS

    def __post_init__(self) -> None:
        if self.pieces is None:  # one piece per beam, hole to hole, of its length's mass
            n = len(self.beams)
            length = np.linalg.norm(
                self.paths[self.beams[:, 1], 0] - self.paths[self.beams[:, 0], 0], axis=1
            )
            object.__setattr__(self, "pieces", np.arange(n, dtype=np.int64))
            object.__setattr__(self, "piece_span", np.stack([np.zeros(n), length], axis=1))
            object.__setattr__(self, "piece_layer", self.layer.astype(np.int64))
            object.__setattr__(self, "piece_kg", np.maximum(length, 0.5) * BEAM_KG_PER_MODULE)

    def piece_ends(self, poses: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Returns (P, K, 2, 2) each piece's end holes at the poses (indices into the A
        angles; all by default), in modules."""
        start = self.paths[self.beams[self.pieces, 0]][:, poses]  # (P, K, 2)
        end = self.paths[self.beams[self.pieces, 1]][:, poses]
        direction = end - start
        unit = direction / np.maximum(np.linalg.norm(direction, axis=-1, keepdims=True), 1e-12)
        t = self.piece_span[:, None, :, None]  # (P, 1, 2, 1)
        return start[:, :, None, :] + t * unit[:, :, None, :]

    @property
    def piece_part(self) -> np.ndarray:
        """(P,) each piece's rigid part (its beam's)."""
        return self.part[self.pieces]

    @property
    def n_parts(self) -> int:
        """Moving parts (bodies), the crank included."""
        return int(self.part.max()) + 1

    def pose_index(self, phase):
        """Returns the index of the pose (of the A sampled crank angles) nearest crank angle
        `phase` (radians): an int for a number, (T,) int64 for (T,) angles."""
        n = self.paths.shape[1]
        index = np.round(np.asarray(phase, dtype=float) / (2 * np.pi) * n).astype(np.int64) % n
        return int(index) if index.ndim == 0 else index

    def pose(self, phase: float) -> np.ndarray:
        """Returns (M, 2) the node positions at crank angle `phase` (radians), rounded to
        the nearest of the A sampled angles."""
        return self.paths[:, self.pose_index(phase)]

    def foot_path(self) -> np.ndarray:
        """Returns (A, 2) the foot's path over one turn."""
        return self.paths[self.foot]

    def fastest_joint_mm_per_deg(self) -> float:
        """Returns how far the fastest node moves per degree of crank at its fastest over the
        turn (mm): near a toggle a part whips round and this runs to tens or hundreds of mm,
        where most study legs' stay below 10 (docs/walking.md, "Where the lean model breaks
        down")."""
        n = self.paths.shape[1]
        steps = np.linalg.norm(np.roll(self.paths, -1, axis=1) - self.paths, axis=2)  # (M, A)
        return float(steps.max() * UNIT_M * 1000 * n / 360)

    def facing(self) -> int:
        """Returns +1 when the foot moves towards +x over the lower half of its path (the
        stance) as the crank turns counter-clockwise, pushing the robot towards -x, else -1.
        A builder mounts the leg so that its stance pushes the robot forwards, so the
        robot's front is at -x times this in the linkage's frame."""
        path = self.foot_path()
        low = path[:, 1] <= (path[:, 1].min() + path[:, 1].max()) / 2
        step = np.diff(path[:, 0], append=path[:1, 0])
        return 1 if step[low].sum() >= 0 else -1

    def stance_stroke(self) -> float:
        """Returns the stance stroke in modules: the horizontal extent of the foot path,
        the furthest a foot that does not slip can push the robot in one stance."""
        x = self.foot_path()[:, 0]
        return float(x.max() - x.min())

    def crank_share(self) -> float:
        """Returns how much of the crank's turn reaches the foot as a turn about the motor's
        axle over the stance (the lower half of the foot's path): 1 for a foot that rides
        the crank as a wheel's rim does, near 0 for a foot pushed along a flat stance."""
        path = self.foot_path()
        axle = self.paths[self.frame_nodes[0], 0]
        low = path[:, 1] <= (path[:, 1].min() + path[:, 1].max()) / 2
        angle = np.arctan2(path[:, 1] - axle[1], path[:, 0] - axle[0])
        turn = np.angle(np.exp(1j * (np.roll(angle, -1) - angle)))  # (A,) each step's turn
        both = low & np.roll(low, -1)
        crank = both.sum() * 2 * np.pi / len(path)
        return float(abs(turn[both].sum()) / crank) if crank else 0.0

    def shape(self) -> dict[str, float | list[float]]:
        """Returns what a builder sees of the leg, in cm: its size over the turn (every
        node's reach, width and height), its stance stroke and lift, and its crank share
        (`crank_share`), rounded for a document."""
        cm = UNIT_M * 100
        reach = np.ptp(self.paths.reshape(-1, 2), axis=0) * cm
        return {
            "size_cm": [round(float(v), 1) for v in reach],
            "stroke_cm": round(self.stance_stroke() * cm, 1),
            "lift_cm": round(float(np.ptp(self.foot_path()[:, 1])) * cm, 1),
            "crank_share": round(self.crank_share(), 2),
        }


@dataclass(frozen=True)
class LegRecipe:
    """What fixes a leg: its linkage (one decoded row: the LEGO build, or the linkage as
    evolved) and each beam's layer, with a digest of the leg it makes. Cells whose recipes
    have one key have one leg (its poses, beams, parts, layers, frame and foot), so a walk
    map walks it once.

    Attributes:
        batch: the linkage, one row.
        layer: (B,) int64 each beam's layer (`sim.robot.layers.layer_plan`).
        note: why the leg is as evolved, or "" for a LEGO build.
        key: the digest of the leg.
        parts: the LEGO build's real parts (`sim.robot.parts.assign_parts`); None as
            evolved.
    """

    batch: LinkageBatch
    layer: np.ndarray
    note: str
    key: str
    parts: PartsBuild | None = None

    def leg(self) -> Leg:
        """Returns the leg (its poses simulated at `POSE_ANGLES` crank angles)."""
        motion = simulate(self.batch, POSE_ANGLES)
        return _leg(self.batch, motion, self.layer, self.note, self.parts)


def _leg(
    batch: LinkageBatch, motion, layer: np.ndarray, note: str, parts: PartsBuild | None
) -> Leg:
    """The leg of a one-row linkage, its motion at `POSE_ANGLES`, its beams' layers and its
    real parts (None: one piece per beam)."""
    n_beams = int(batch.n_beams[0])
    beams = batch.beam_int[0, :n_beams, :2].astype(np.int64)
    kinds = [NODE_KINDS[int(k)] for k in batch.node_int[0, :, 0]]
    frame_nodes = [j for j, kind in enumerate(kinds) if kind in ("motor", "static")]
    return Leg(
        paths=motion.positions[0],
        beams=beams,
        part=rigid_parts(batch.node_int[0], beams, frame_nodes),
        layer=layer,
        frame_nodes=np.array(frame_nodes, dtype=np.int64),
        foot=int(motion.foot[0]),
        built=not note,
        note=note,
        **(_pieces(parts) if parts is not None else {}),
    )


def _pieces(parts: PartsBuild) -> dict[str, np.ndarray]:
    """A build's physical beams as `Leg`'s piece arrays."""
    pieces = parts.pieces
    return {
        "pieces": np.array([p.beam for p in pieces], dtype=np.int64),
        "piece_span": np.array([(p.t0, p.t1) for p in pieces], dtype=np.float64),
        "piece_layer": np.array([p.layer for p in pieces], dtype=np.int64),
        "piece_kg": np.array([p.part.mass_kg for p in pieces], dtype=np.float64),
        "most_spacers": min(MAX_SPACERS, parts.most_spacers),
    }


def _digest(leg: Leg) -> str:
    """A digest of everything a walk reads of a leg."""
    digest = hashlib.sha1(f"{leg.foot} {leg.built} {leg.most_spacers}".encode())
    arrays = (leg.paths, leg.beams, leg.part, leg.layer, leg.frame_nodes, leg.pieces)
    for array in (*arrays, leg.piece_span, leg.piece_layer, leg.piece_kg):
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def leg_from_genome(genome: np.ndarray, mode: str = "paper") -> Leg:
    """Returns the leg of a genome: its LEGO build (as `linkevo pull` makes it) where a
    whole-module rounding turns and real parts build it, else the linkage as evolved.

    Args:
        genome: (56,) genes.
        mode: "paper" or "legacy".

    Raises:
        LegError: when the linkage (as built and as evolved) does not turn a full turn.
    """
    return recipe_and_leg(genome, mode)[1]


def leg_recipe(genome: np.ndarray, mode: str = "paper") -> LegRecipe:
    """Returns the recipe of `leg_from_genome`'s leg; raises as it does."""
    return recipe_and_leg(genome, mode)[0]


def recipe_and_leg(
    genome: np.ndarray, mode: str = "paper", searched: np.ndarray | None = None
) -> tuple[LegRecipe, Leg]:
    """Returns `leg_recipe`'s recipe and `leg_from_genome`'s leg at once; raises as they do.
    `searched` is the build's (15,) lengths where the caller found them for its whole batch
    (`sim.robot.lego.whole_module_build`)."""
    genome = np.asarray(genome, dtype=np.float64).reshape(1, -1)
    note, parts = "", None
    try:
        batch = whole_module_build(genome[0], mode, searched)
        coarse = simulate(batch, DEFAULT_ANGLES)
        plan = layer_plan(batch, coarse)
        parts = assign_parts(batch, coarse, plan)
    except (QuantiseError, LayerError, PartsError) as exc:
        batch, note, plan = decode(genome, mode), f"walked as evolved: {exc}", None
    motion = simulate(batch, POSE_ANGLES)
    valid = motion.valid[0]
    if not valid.all():
        raise LegError(
            f"the linkage does not turn a full turn: it fails to assemble at "
            f"{int((~valid).sum())} of {POSE_ANGLES} crank angles, so no robot can walk on it"
        )
    if plan is None:  # as evolved: no parts, so no fasteners to keep clear
        plan = layer_plan(batch, simulate(batch, DEFAULT_ANGLES), fastened=False)
    leg = _leg(batch, motion, plan.layer, note, parts)
    return LegRecipe(batch, plan.layer, note, _digest(leg), parts), leg


def rigid_parts(node_int: np.ndarray, beams: np.ndarray, frame_nodes: list[int]) -> np.ndarray:
    """Returns (B,) int64 the rigid part of each beam: -1 for the frame, else 0, 1, ... in
    beam order.

    The crank is a part of its own. An extension continues its parent beam's part. A
    triangle whose two anchors already lie on one part (or both on the frame) is a rigid
    truss: both its beams join that part. Any other beam is a part of its own, pinned at
    both ends.

    Args:
        node_int: (12, 4) the decoded nodes [kind, a, c, direction] (`LinkageBatch`).
        beams: (B, 2) each beam's start and end node, in decode order.
        frame_nodes: the motor and static nodes.
    """
    n_beams = len(beams)
    part = np.full(n_beams, -2, dtype=np.int64)
    nodes_of: dict[int, set[int]] = {-1: set(frame_nodes)}
    next_part = 0
    for b in range(n_beams):
        start, end = int(beams[b, 0]), int(beams[b, 1])
        kind = NODE_KINDS[int(node_int[end, 0])]
        if kind == "extension":
            p = int(part[int(node_int[end, 1])])
        elif kind == "triangle":
            a, c = int(node_int[end, 1]), int(node_int[end, 2])
            common = [q for q, members in nodes_of.items() if {a, c} <= members]
            p = common[0] if common else -2
        else:
            p = -2
        if p == -2:
            p, next_part = next_part, next_part + 1
            nodes_of[p] = set()
        part[b] = p
        nodes_of[p] |= {start, end}
    return part
