"""Provides the reference's linkage: decode one genome (spec §1-§2) and simulate it over a
turn (spec §3), as plain dataclasses."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from linkevo.sim.linkage.genome import (
    BLOCK_SIZE,
    CRANK_GENE,
    FIRST_BLOCK,
    N_BLOCKS,
    N_NODES,
    N_STATIC,
    validate_genomes,
)
from linkevo.sim.study import MODES

Point = tuple[float, float]

TOLERANCE = 0.1
"""Tolerance t of circle_intersection (spec §2, as published)."""
MAX_LENGTH = 15.0
MIN_LENGTH = 2.0
MAX_ANCHOR_DISTANCE = 30.0
CONTACT_BAND = 0.5
"""Height of the F_sl contact band above the lowest path point (5 mm)."""
MOTOR = 0
CRANK_TIP = N_STATIC + 1


def fti(gene: float, count: int) -> int:
    """Returns floor(gene * count), the spec's gene-to-integer rule (gene >= 0)."""
    return int(gene * count)


def distance(p: Point, q: Point) -> float:
    """Returns the Euclidean distance |q - p| as sqrt(dx*dx + dy*dy) (docs/simulator.md)."""
    dx = q[0] - p[0]
    dy = q[1] - p[1]
    return math.sqrt(dx * dx + dy * dy)


@dataclass(frozen=True)
class Beam:
    """One rigid beam.

    Attributes:
        start: the node it starts at (an anchor, or where an extension starts).
        end: the node it holds (the crank tip or an added node).
        length: its decoded length.
        kind: "crank", "triangle" or "extension".
        parent: the beam an extension continues; -1 for other kinds.
        inverted: True for an extension that continues its parent backwards.
    """

    start: int
    end: int
    length: float
    kind: str
    parent: int = -1
    inverted: bool = False


@dataclass(frozen=True)
class Triangle:
    """An added node held by beams of lengths l1 from anchor A and l2 from anchor C."""

    node: int
    anchor_a: int
    anchor_c: int
    l1: float
    l2: float
    direction: int
    backup_angle: float


@dataclass(frozen=True)
class Extension:
    """An added node that continues beam `parent` rigidly by `length` (beam index `beam`)."""

    node: int
    beam: int
    parent: int
    inverted: bool
    length: float


@dataclass(frozen=True)
class Linkage:
    """One decoded linkage.

    Attributes:
        mode: "paper" or "legacy".
        crank_length: length of the crank (beam 0).
        blocks: the seven added nodes, in decode order.
        beams: every beam, in decode order.
        nodes: the 12 node positions at crank angle 0.
    """

    mode: str
    crank_length: float
    blocks: tuple[Triangle | Extension, ...]
    beams: tuple[Beam, ...]
    nodes: tuple[Point, ...]

    @property
    def static_nodes(self) -> tuple[Point, ...]:
        """Returns the motor and the static nodes, which never move."""
        return self.nodes[:CRANK_TIP]


@dataclass(frozen=True)
class Pose:
    """Every node position and beam angle at one crank angle."""

    positions: tuple[Point, ...]
    beam_angles: tuple[float, ...]


@dataclass(frozen=True)
class Motion:
    """A linkage simulated over A crank angles.

    Attributes:
        crank_angles: (A,) the crank angle of each sample.
        positions: (12, A, 2) node positions, NaN at failed angles.
        valid: (A,) True where the linkage assembled.
        beam_angles: (B, A) recorded beam angles, NaN at failed angles.
        foot: index of the foot node.
        foot_path: (n, 2) the foot's recorded samples, in angle order.
        foot_angles: (n,) mean angle of the beams that end at the foot, per recorded sample.
    """

    crank_angles: np.ndarray
    positions: np.ndarray
    valid: np.ndarray
    beam_angles: np.ndarray
    foot: int
    foot_path: np.ndarray
    foot_angles: np.ndarray

    @property
    def error(self) -> int:
        """Returns the number of failed crank angles."""
        return int((~self.valid).sum())


def check_mode(mode: str) -> None:
    """Raises ValueError unless `mode` is "paper" or "legacy"."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")


def circle_intersection(
    p0: Point, p1: Point, r0: float, r1: float, direction: int, backup_angle: float, mode: str
) -> Point | None:
    """Returns a point at distance r0 from p0 and r1 from p1 (spec §2), or None.

    `direction` picks the intersection (0: to the right of p0 -> p1, 1: to the left);
    `backup_angle` places the point when the circles coincide. Inside the tolerance band
    the distance is nudged by t and used for the unit vector p0 -> p1 too, as published.
    """
    dx = p1[0] - p0[0]
    dy = p1[1] - p0[1]
    d = math.sqrt(dx * dx + dy * dy)
    if d - TOLERANCE > r0 + r1 or d + TOLERANCE < abs(r0 - r1):
        return None
    if d == 0.0 and r0 == r1:
        centre = (0.0, 0.0) if mode == "legacy" else p0
        return (centre[0] + r0 * math.cos(backup_angle), centre[1] + r0 * math.sin(backup_angle))
    nudged = d
    if d > r0 + r1:
        nudged = d - TOLERANCE
    elif d < abs(r0 - r1):
        nudged = d + TOLERANCE
    inv = 1.0 / nudged
    ex = dx * inv
    ey = dy * inv
    if mode == "legacy" and abs(d - r0 + r1) < TOLERANCE:
        return (p0[0] + r0 * ex, p0[1] + r0 * ey)
    a = 0.5 * (r0 * r0 - r1 * r1 + nudged * nudged) * inv
    h = math.sqrt(max(r0 * r0 - a * a, 0.0))
    mx = p0[0] + a * ex
    my = p0[1] + a * ey
    if direction == 0:
        return (mx + h * ey, my - h * ex)
    return (mx - h * ey, my + h * ex)


def unit_vector(start: Point, end: Point) -> Point:
    """Returns the unit vector start -> end; (1, 0) when they coincide (atan2(0, 0) = 0)."""
    dx = end[0] - start[0]
    dy = end[1] - start[1]
    norm = math.sqrt(dx * dx + dy * dy)
    if norm == 0.0:
        return (1.0, 0.0)
    inv = 1.0 / norm
    return (dx * inv, dy * inv)


def beam_angle(start: Point, end: Point) -> float:
    """Returns the angle of the beam start -> end, in [0, 2 pi) (spec §2, "Triangle").

    atan2's (-pi, pi] is moved up by 2 pi where negative, the published code's very
    addition, so the bits match it.
    """
    angle = math.atan2(end[1] - start[1], end[0] - start[0])
    if angle < 0.0:
        angle += 2.0 * math.pi
    return angle


@dataclass
class Frame:
    """Working state while placing nodes at one crank angle, in decode order.

    Attributes:
        positions: node positions placed so far.
        directions: unit direction (start -> end) of each beam placed so far.
        angles: recorded angle of each beam placed so far (docs/simulator.md).
    """

    positions: list[Point]
    directions: list[Point]
    angles: list[float]

    @staticmethod
    def start(static_nodes: tuple[Point, ...], crank_length: float, theta: float) -> Frame:
        """Returns the frame with the motor, static nodes and crank tip at angle theta."""
        c, s = math.cos(theta), math.sin(theta)
        tip = (crank_length * c, crank_length * s)
        return Frame([*static_nodes, tip], [(c, s)], [theta])

    def place(self, block: Triangle | Extension, beams: tuple[Beam, ...], mode: str) -> bool:
        """Places the block's node and its beams; returns False if a triangle fails."""
        if isinstance(block, Extension):
            ux, uy = self.directions[block.parent]
            angle = self.angles[block.parent]
            parent = beams[block.parent]
            start = parent.end
            if block.inverted:
                ux, uy, angle, start = -ux, -uy, angle + math.pi, parent.start
            x, y = self.positions[start]
            self.positions.append((x + block.length * ux, y + block.length * uy))
            self.directions.append((ux, uy))
            self.angles.append(angle)
            return True
        a = self.positions[block.anchor_a]
        c = self.positions[block.anchor_c]
        point = circle_intersection(
            a, c, block.l1, block.l2, block.direction, block.backup_angle, mode
        )
        if point is None:
            return False
        self.positions.append(point)
        for anchor in (a, c):
            self.directions.append(unit_vector(anchor, point))
            self.angles.append(beam_angle(anchor, point))
        return True


def repair_anchor_c(a: int, c: int, positions: list[Point]) -> int:
    """Returns anchor C after the spec's repair loop (spec §2, docs/simulator.md).

    C is decremented (1 wraps to the last node) while it equals A, is over 30 from A or is
    under 0.1 from A; once C comes back to its first value the loop runs again without the
    "under 0.1" test, and stops at the first value if it comes back again.
    """
    first = c
    for test_near in (True, False):
        while (
            c == a
            or distance(positions[a], positions[c]) > MAX_ANCHOR_DISTANCE
            or (test_near and distance(positions[a], positions[c]) < TOLERANCE)
        ):
            c = c - 1 if c > 1 else len(positions) - 1
            if c == first:
                break
        else:
            return c
    return c


def decode_block(g: list[float], i: int, beams: list[Beam], frame: Frame, mode: str):
    """Returns block i (Triangle or Extension) read from genes g, at the frame's positions."""
    o = FIRST_BLOCK + BLOCK_SIZE * i
    node = len(frame.positions)
    if fti(g[o], 4) == 0:
        length = 12.0 * g[CRANK_GENE] + 3.0 if mode == "legacy" else 2.0 + 13.0 * g[o + 6]
        return Extension(node, len(beams), fti(g[o + 1], len(beams)), fti(g[o + 3], 2) == 1, length)
    a = fti(g[o + 1], node - 1) + 1
    c = repair_anchor_c(a, fti(g[o + 2], node - 1) + 1, frame.positions)
    d = distance(frame.positions[a], frame.positions[c])
    s1 = max(d - MAX_LENGTH, MIN_LENGTH)
    l1 = (MAX_LENGTH - s1) * g[o + 5] + s1
    lo = abs(d - l1)
    hi = min(d + l1, MAX_LENGTH)
    l2 = (hi - lo) * g[o + 6] + lo
    return Triangle(node, a, c, l1, l2, fti(g[o + 3], 2), 2.0 * math.pi * g[o + 4])


def decode_linkage(genome: np.ndarray, mode: str = "paper") -> Linkage:
    """Returns the linkage a genome (56,) encodes, with its nodes at crank angle 0."""
    check_mode(mode)
    g = [float(v) for v in validate_genomes(np.asarray(genome)[None, :])[0]]
    static_nodes = [(0.0, 0.0)]
    for j in range(N_STATIC):
        static_nodes.append((fti(g[2 * j], 11) - 5.0, fti(g[2 * j + 1], 11) - 5.0))
    crank_length = 2.0 + 6.0 * g[CRANK_GENE]
    frame = Frame.start(tuple(static_nodes), crank_length, 0.0)
    beams = [Beam(MOTOR, CRANK_TIP, crank_length, "crank")]
    blocks: list[Triangle | Extension] = []
    for i in range(N_BLOCKS):
        block = decode_block(g, i, beams, frame, mode)
        if isinstance(block, Extension):
            parent = beams[block.parent]
            start = parent.start if block.inverted else parent.end
            beams.append(
                Beam(start, block.node, block.length, "extension", block.parent, block.inverted)
            )
        else:
            beams.append(Beam(block.anchor_a, block.node, block.l1, "triangle"))
            beams.append(Beam(block.anchor_c, block.node, block.l2, "triangle"))
        if not frame.place(block, tuple(beams), mode):
            raise RuntimeError(f"block {i} does not assemble at crank angle 0 (spec §2): {g}")
        blocks.append(block)
    return Linkage(mode, crank_length, tuple(blocks), tuple(beams), tuple(frame.positions))


def pose(linkage: Linkage, theta: float) -> Pose | None:
    """Returns every node and beam angle at crank angle theta, or None if it fails."""
    frame = Frame.start(linkage.static_nodes, linkage.crank_length, theta)
    for block in linkage.blocks:
        if not frame.place(block, linkage.beams, linkage.mode):
            return None
    return Pose(tuple(frame.positions), tuple(frame.angles))


def crank_angles(n_angles: int, mode: str) -> list[float]:
    """Returns the A crank angles: k*2*pi/A (paper) or accumulated steps (legacy)."""
    if mode == "paper":
        return [k * 2.0 * math.pi / n_angles for k in range(n_angles)]
    step = 2.0 * math.pi / n_angles
    thetas = [0.0]
    for _ in range(n_angles - 1):
        thetas.append(thetas[-1] + step)
    return thetas


def simulate_linkage(linkage: Linkage, n_angles: int = 40) -> Motion:
    """Returns the motion of a linkage over `n_angles` crank angles, in its mode (spec §3)."""
    thetas = crank_angles(n_angles, linkage.mode)
    poses = [pose(linkage, theta) for theta in thetas]
    recorded = [p for p in poses if p is not None]
    lowest = [min(p.positions[n][1] for p in recorded) for n in range(N_NODES)]
    foot = min(range(N_NODES), key=lambda n: (lowest[n], n))
    into_foot = [b for b, beam in enumerate(linkage.beams) if beam.end == foot]
    foot_angles = [
        sum(p.beam_angles[b] for b in into_foot) / len(into_foot) if into_foot else 0.0
        for p in recorded
    ]
    failed = Pose(((math.nan, math.nan),) * N_NODES, (math.nan,) * len(linkage.beams))
    filled = [failed if p is None else p for p in poses]
    return Motion(
        crank_angles=np.array(thetas),
        positions=np.array([p.positions for p in filled]).transpose(1, 0, 2),
        valid=np.array([p is not None for p in poses]),
        beam_angles=np.array([p.beam_angles for p in filled]).T,
        foot=foot,
        foot_path=np.array([p.positions[foot] for p in recorded]),
        foot_angles=np.array(foot_angles),
    )
