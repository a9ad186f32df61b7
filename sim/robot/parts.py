"""Provides `assign_parts`: a LEGO build's real Technic parts, the ones a shop sells
(`technic_parts.json`, from the LDraw parts library).

A linkage's LEGO build (`sim.robot.lego`) has whole-module beams on layers
(`sim.robot.layers`); Technic sells straight thick beams of 1, 2, 3, 5, 7, 9, 11, 13 and 15
holes only, pins of two and three layers, and axles. So each **bar** of the build (a beam
and every extension of it: one straight run whose holes are its nodes) is built as:

- **one beam** when it spans at most 14 modules: the smallest with enough holes. A bar
  needing an even number of holes gets one more, a module of **overhang** past one of its
  end holes, placed at the end where it strikes nothing over the turn;
- **beams joined side by side** when it spans more (the layer plan gives it two layers):
  15-hole beams alternating between its two layers, each overlapping the last by two holes
  or more and locked to it by two friction pins, the last as short as the rest allows.

Each **joint** (a node where bars on different layers meet) gets a fastener across the
layers from its lowest to its highest: a frictionless pin of two or three layers (a
one-hole beam, "spacer", filling a layer between with no beam at the node), else an axle
through round holes held by half bushes, bushes filling the empty layers. A frame node is
an axle from the frame's hole, and the motor drives the crank through a driver liftarm on
its axle (`technic_parts.json`, "driver"), on layer -1 between the frame and the leg.

An assignment exists only when nothing strikes: an overhang, a filler or a fastener's end
(every layer a fastener passes without a hole of its own) must come no closer to another
bar on its layer than a beam's half width and the part's own over the turn. When none
exists the build is refused with the reason (`PartsError`), as a rounding that does not
turn is.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from linkevo.sim.errors import LinkevoError
from linkevo.sim.linkage.decoding import NODE_KINDS, LinkageBatch
from linkevo.sim.linkage.kinematics import Motion
from linkevo.sim.robot.layers import LONGEST_PIN, LayerPlan, bar_of, segment_distance

CATALOGUE_FILE = Path(__file__).with_name("technic_parts.json")
BEAM_HALF_WIDTH = 0.45
"""Half a thick beam's 7.2 mm width, in modules."""
PIN_RADIUS = 0.3
"""A pin's or an axle's radius with its bush or spacer's collar, in modules (4.8 mm across,
a spacer's 7.2 mm: the larger, half of 0.9, is taken for fillers)."""
FILLER_RADIUS = 0.45
"""A one-hole beam or a bush filling a layer at a joint: a beam's half width."""
CLEARANCE = 0.05
"""What parts on one layer must keep apart beyond their half widths, in modules."""
OVERLAP_HOLES = 2
"""Holes two joined beams share at least (two pins lock them)."""
MOTOR_AXLE_EXTRA = 3
"""Modules of motor axle beyond the spacers: its grip in the horn, the driver and the crank
(held on by the driver's pin)."""
FRAME_AXLE_EXTRA = 4
"""Modules of a frame pivot's axle beyond the spacers and its beams' layers: its grip in
the frame, the driver's layer and the half bush at its end."""


class PartsError(LinkevoError, ValueError):
    """No assignment of real Technic parts builds the linkage; says what strikes what."""


@dataclass(frozen=True)
class Part:
    """One catalogue part.

    Attributes:
        number: the LDraw part number (`parts/<number>.dat`).
        name: its LDraw name.
        kind: "beam", "pin", "axle", "bush" or "driver".
        size: holes (beam, driver), layers (pin, bush) or length in modules (axle).
        mass_kg: its mass.
        bricklink: BrickLink's item number.
        friction: a pin with friction ridges.
    """

    number: str
    name: str
    kind: str
    size: float
    mass_kg: float
    bricklink: str
    friction: bool = False


@dataclass(frozen=True)
class Catalogue:
    """The parts a leg may use, with the catalogue's source (`technic_parts.json`)."""

    beams: tuple[Part, ...]
    pins: tuple[Part, ...]
    axles: tuple[Part, ...]
    bushes: tuple[Part, ...]
    driver: Part
    source: str

    def beam(self, holes: int) -> Part:
        """The smallest beam with at least `holes` holes (PartsError past the longest)."""
        for part in self.beams:
            if part.size >= holes:
                return part
        raise PartsError(f"no Technic beam has {holes} holes (the longest has {self.longest})")

    @property
    def longest(self) -> int:
        return int(self.beams[-1].size)

    def pin(self, layers: int, friction: bool = False) -> Part:
        return next(p for p in self.pins if p.size == layers and p.friction == friction)

    def axle(self, length: int) -> Part:
        """The shortest axle at least `length` modules long."""
        for part in self.axles:
            if part.size >= length:
                return part
        longest = self.axles[-1].size
        raise PartsError(f"no Technic axle is {length} modules long (the longest: {longest:g})")

    def bush(self, layers: float) -> Part:
        return next(p for p in self.bushes if p.size == layers)

    def part(self, number: str) -> Part:
        """The part of this LDraw number."""
        for part in (*self.beams, *self.pins, *self.axles, *self.bushes, self.driver):
            if part.number == number:
                return part
        raise KeyError(number)


@functools.cache
def catalogue() -> Catalogue:
    """Returns the parts catalogue (`technic_parts.json`), read once."""
    raw = json.loads(CATALOGUE_FILE.read_text(encoding="utf-8"))

    def parts(key: str, kind: str, size: str) -> tuple[Part, ...]:
        return tuple(
            Part(
                number=e["part"],
                name=e["name"],
                kind=kind,
                size=float(e[size]),
                mass_kg=float(e["mass_g"]) / 1000.0,
                bricklink=e.get("bricklink", e["part"]),
                friction=bool(e.get("friction", False)),
            )
            for e in raw[key]
        )

    driver = raw["driver"]
    return Catalogue(
        beams=tuple(sorted(parts("beams", "beam", "holes"), key=lambda p: p.size)),
        pins=parts("pins", "pin", "layers"),
        axles=tuple(sorted(parts("axles", "axle", "length"), key=lambda p: p.size)),
        bushes=parts("bushes", "bush", "layers"),
        driver=Part(
            driver["part"],
            driver["name"],
            "driver",
            float(driver["holes"]),
            float(driver["mass_g"]) / 1000.0,
            driver["part"],
        ),
        source=raw["source"],
    )


@dataclass(frozen=True)
class Piece:
    """One physical beam of the build.

    Attributes:
        part: the catalogue beam.
        beam: the linkage beam it lies along (its bar's first beam).
        t0, t1: its end holes, in modules along `beam` from the beam's start node.
        layer: its layer (0 nearest the frame).
        bar: its bar's index.
    """

    part: Part
    beam: int
    t0: int
    t1: int
    layer: int
    bar: int


@dataclass(frozen=True)
class Joint:
    """What holds the beams at one node together.

    Attributes:
        node: the node.
        layers: the layers of the beams with a hole at the node, lowest first (-1: the
            driver's, at the motor).
        frame: the node is fixed to the frame (the motor's or a static node).
        fastener: the pin or axle.
        fillers: (part, layer) the parts filling layers with no beam at the node (one-hole
            beams on a pin, bushes on an axle) and an axle's half bushes (a quarter of a
            layer past its end beams: layer +- 0.75).
        occupied: every layer the fastener and fillers take at the node, lowest first.
    """

    node: int
    layers: tuple[int, ...]
    frame: bool
    fastener: Part
    fillers: tuple[tuple[Part, float], ...]
    occupied: tuple[int, ...]


@dataclass(frozen=True)
class PartsBuild:
    """A leg's real parts (`assign_parts`).

    Attributes:
        pieces: every physical beam.
        joints: every joint's fastener and fillers (the frame nodes' without spacers:
            `mounted_joints` adds the robot's).
        locks: the friction pins locking joined beams, as (bar, hole t along the bar).
        bar_of: each linkage beam's bar (a beam and its extensions: one straight run).
        driver: the motor's driver liftarm.
    """

    pieces: tuple[Piece, ...]
    joints: tuple[Joint, ...]
    locks: tuple[tuple[int, int], ...]
    bar_of: tuple[int, ...] = ()
    driver: Part = field(default_factory=lambda: catalogue().driver)

    @property
    def most_spacers(self) -> int:
        """The most spacer layers its frame axles can pass and stay within the longest
        Technic axle (`mounted_joints`)."""
        longest = catalogue().axles[-1].size
        return int(longest - max(j.fastener.size for j in self.joints if j.frame))

    def counts(self, spacers: int = 0) -> dict[str, int]:
        """Returns each part number's count in one leg mounted `spacers` layers out: its
        beams, fasteners and fillers, lock pins, the driver, the motor axle and its bushes."""
        out: dict[str, int] = {}

        def add(part: Part, n: int = 1) -> None:
            out[part.number] = out.get(part.number, 0) + n

        cat = catalogue()
        for piece in self.pieces:
            add(piece.part)
        for joint in mounted_joints(self, spacers):
            add(joint.fastener)
            for part, _ in joint.fillers:
                add(part)
        if self.locks:
            add(cat.pin(2, friction=True), len(self.locks))
        add(self.driver)
        add(cat.pin(2, friction=True))  # the driver's pin into the crank
        return out


def mounted_joints(build: PartsBuild, spacers: int) -> list[Joint]:
    """Returns the build's joints with the frame nodes' axles lengthened through `spacers`
    layers of bushes (`sim.robot.mounting`): the motor's axle passes them, the driver and
    the crank; a frame pivot's passes them and every layer up to its highest beam."""
    cat = catalogue()
    out = []
    for joint in build.joints:
        if not joint.frame or not spacers:
            out.append(joint)
            continue
        length = joint.fastener.size + spacers
        bushes = tuple((cat.bush(1), -2.0 - k) for k in range(spacers))  # frame side of -1
        out.append(
            Joint(
                joint.node,
                joint.layers,
                True,
                cat.axle(int(length)),
                joint.fillers + bushes,
                joint.occupied,
            )
        )
    return out


@dataclass(frozen=True)
class _Bar:
    """A straight run of the build: its first beam, its beams, each node's hole along the
    first beam (modules from its start node) and its layer and width."""

    beam: int
    beams: tuple[int, ...]
    holes: dict[int, int]
    layer: int
    width: int

    @property
    def span(self) -> int:
        return max(self.holes.values()) - min(self.holes.values())


def assign_parts(batch: LinkageBatch, motion: Motion, plan: LayerPlan, i: int = 0) -> PartsBuild:
    """Returns the real parts of linkage i's LEGO build (module docstring).

    Args:
        batch: the whole-module linkages; motion: their simulation (the angles the
            strike checks sample); plan: linkage i's layer plan.

    Raises:
        PartsError: naming what would strike what, where no assignment exists.
    """
    bars = _bars(batch, plan, i)
    pos = motion.positions[i][:, motion.valid[i]]  # (12, A', 2)
    ends = batch.beam_int[i, : int(batch.n_beams[i]), :2]
    kinds = [NODE_KINDS[int(k)] for k in batch.node_int[i, :, 0]]
    frame_nodes = {n for n, kind in enumerate(kinds) if kind in ("motor", "static")}

    def along(bar: _Bar, t: float) -> np.ndarray:
        """(A', 2) the point t modules along the bar's first beam, over the turn."""
        s, e = int(ends[bar.beam, 0]), int(ends[bar.beam, 1])
        d = pos[e] - pos[s]
        return pos[s] + t * d / np.linalg.norm(d, axis=-1, keepdims=True)

    cat = catalogue()
    pieces: list[Piece] = []
    locks: list[tuple[int, int]] = []
    for k, bar in enumerate(bars):
        low, high = min(bar.holes.values()), max(bar.holes.values())
        if bar.width == 1:
            part = cat.beam(bar.span + 1)
            pieces.append(Piece(part, bar.beam, low, low + int(part.size) - 1, bar.layer, k))
            continue
        start, layer = low, bar.layer
        while True:
            part = cat.beam(min(high - start + 1, cat.longest))
            t0 = min(start, high - int(part.size) + 1)  # the last beam: more overlap, no overhang
            pieces.append(Piece(part, bar.beam, t0, t0 + int(part.size) - 1, layer, k))
            if t0 + part.size - 1 >= high:
                break
            start = t0 + int(part.size) - OVERLAP_HOLES
            shared = range(start, t0 + int(part.size))
            locks += [(k, t) for t in shared if t not in bar.holes.values()][:OVERLAP_HOLES]
            layer = 2 * bar.layer + 1 - layer
    joints = _joints(bars, pieces, frame_nodes)
    for n, piece in enumerate(pieces):  # each overhang past the end hole that strikes nothing
        high = max(bars[piece.bar].holes.values())
        if piece.t1 <= high:
            continue
        others = pieces[:n] + pieces[n + 1 :]
        for option in (piece, _shifted(piece, high - piece.t1)):
            if not _overhang_strikes(option, bars, others, joints, along):
                pieces[n] = option
                break
        else:
            raise PartsError(
                f"the overhang of bar b{piece.beam}'s {int(piece.part.size)}-hole beam (layer "
                f"{piece.layer}) strikes another beam or a pin over the turn at either end"
            )
    for joint in joints:
        _check_joint(joint, bars, pieces, along, pos)
    # The driver: on the motor's axle just inside the crank, pinned to its second hole.
    layer = bars[0].layer - 1
    p, q = pos[0], along(bars[0], 1.0)
    for piece in pieces:
        if piece.layer == layer:
            bar = bars[piece.bar]
            d = segment_distance(p, q, along(bar, piece.t0), along(bar, piece.t1))
            if (d < 2 * BEAM_HALF_WIDTH + CLEARANCE).any():
                raise PartsError(
                    f"the motor's driver liftarm (layer {layer}) meets bar b{bar.beam}"
                )
    for joint in joints:
        clear = joint.node == 0 or layer not in joint.occupied
        if not clear and (segment_distance(p, q, pos[joint.node], pos[joint.node]) < 0.9).any():
            raise PartsError(
                f"the motor's driver liftarm (layer {layer}) meets the pin or axle at node "
                f"{joint.node} over the turn"
            )
    bar_of = [0] * int(batch.n_beams[i])
    for k, bar in enumerate(bars):
        for b in bar.beams:
            bar_of[b] = k
    return PartsBuild(tuple(pieces), tuple(joints), tuple(locks), tuple(bar_of))


def _shifted(piece: Piece, by: int) -> Piece:
    return Piece(piece.part, piece.beam, piece.t0 + by, piece.t1 + by, piece.layer, piece.bar)


def _bars(batch: LinkageBatch, plan: LayerPlan, i: int) -> list[_Bar]:
    """The build's bars: each beam with its extensions, holes at whole modules."""
    n_beams = int(batch.n_beams[i])
    parent = batch.beam_int[i, :n_beams, 3]
    ends = batch.beam_int[i, :n_beams, :2]
    length = np.rint(batch.beam_length[i, :n_beams]).astype(int)
    base = bar_of(batch, i)
    bars = []
    for first in np.unique(base):
        members = [int(b) for b in np.flatnonzero(base == first)]
        at = {int(ends[first, 0]): 0, int(ends[first, 1]): int(length[first])}
        for b in members[1:]:
            s, e, p = int(ends[b, 0]), int(ends[b, 1]), int(parent[b])
            ahead = at[int(ends[p, 1])] >= at[int(ends[p, 0])]
            at[e] = at[s] + (int(length[b]) if (s == int(ends[p, 1])) == ahead else -int(length[b]))
        bars.append(
            _Bar(int(first), tuple(members), at, int(plan.layer[first]), int(plan.width[first]))
        )
    return bars


def _joints(bars: list[_Bar], pieces: list[Piece], frame_nodes: set[int]) -> list[Joint]:
    """Each node's fastener: the layers of the pieces with a hole there (and the driver's
    at the motor, the frame's at a static node), spanned by a pin or an axle."""
    cat = catalogue()
    layers: dict[int, set[int]] = {}
    for piece in pieces:
        for node, t in bars[piece.bar].holes.items():
            if piece.t0 <= t <= piece.t1:
                layers.setdefault(node, set()).add(piece.layer)
    out = []
    for node in sorted(layers):
        held = sorted(layers[node])
        frame = node in frame_nodes
        if frame:
            top = held[-1]
            if node == 0:  # the motor's axle: bushes, the driver (just inside), the crank
                fastener = cat.axle(top + MOTOR_AXLE_EXTRA)
                fillers = tuple((cat.bush(1), float(layer)) for layer in range(-1, top - 1))
                occupied = tuple(range(-1, top + 1))
            else:  # a pivot's axle from the frame's hole, held by a half bush at its end
                empty = [layer for layer in range(-1, top + 1) if layer not in held]
                fastener = cat.axle(top + FRAME_AXLE_EXTRA)
                fillers = tuple((cat.bush(1), float(layer)) for layer in empty)
                fillers += ((cat.bush(0.5), top + 0.75),)
                occupied = tuple(range(-1, top + 2))
            out.append(Joint(node, tuple(held), True, fastener, fillers, occupied))
            continue
        if len(held) < 2:
            continue  # one bar passes through: no joint
        span = held[-1] - held[0] + 1
        empty = [layer for layer in range(held[0], held[-1] + 1) if layer not in held]
        if span <= LONGEST_PIN:
            fastener = cat.pin(span)
            fillers = tuple((cat.beam(1), float(layer)) for layer in empty)
            occupied = tuple(range(held[0], held[-1] + 1))
        else:
            fastener = cat.axle(span + 1)
            fillers = tuple((cat.bush(1), float(layer)) for layer in empty)
            fillers += ((cat.bush(0.5), held[0] - 0.75), (cat.bush(0.5), held[-1] + 0.75))
            occupied = tuple(range(held[0] - 1, held[-1] + 2))
        out.append(Joint(node, tuple(held), False, fastener, fillers, occupied))
    return out


def _overhang_strikes(piece: Piece, bars, others: list[Piece], joints, along) -> bool:
    """Whether a piece's overhang (past its bar's first or last hole) comes near another
    bar's piece on its layer, or a fastener or filler on its layer, over the turn."""
    bar = bars[piece.bar]
    low, high = min(bar.holes.values()), max(bar.holes.values())
    for a, b in ((piece.t0, low), (high, piece.t1)):
        if b <= a:
            continue
        p, q = along(bar, a), along(bar, b)
        for other in others:
            if other.bar != piece.bar and other.layer == piece.layer:
                ob = bars[other.bar]
                d = segment_distance(p, q, along(ob, other.t0), along(ob, other.t1))
                if (d < 2 * BEAM_HALF_WIDTH + CLEARANCE).any():
                    return True
        for joint in joints:
            if piece.layer in joint.occupied and joint.node not in bar.holes:
                where = _node_path(bars, joint.node, along)
                if (segment_distance(p, q, where, where) < BEAM_HALF_WIDTH + FILLER_RADIUS).any():
                    return True
    return False


def _node_path(bars: list[_Bar], node: int, along) -> np.ndarray:
    bar = next(b for b in bars if node in b.holes)
    return along(bar, bar.holes[node])


def _check_joint(joint: Joint, bars, pieces, along, pos) -> None:
    """Raises PartsError when a piece without a hole at the joint passes its fastener or
    fillers on a layer they take, over the turn."""
    where = pos[joint.node]
    for piece in pieces:
        bar = bars[piece.bar]
        holed = joint.node in bar.holes and piece.t0 <= bar.holes[joint.node] <= piece.t1
        if piece.layer not in joint.occupied or holed:
            continue
        d = segment_distance(along(bar, piece.t0), along(bar, piece.t1), where, where)
        if (d < BEAM_HALF_WIDTH + FILLER_RADIUS).any():
            what = "axle" if joint.fastener.kind == "axle" else "pin"
            raise PartsError(
                f"the {what} at node {joint.node} (layers {joint.occupied[0]} to "
                f"{joint.occupied[-1]}) meets bar b{bar.beam} on layer {piece.layer} over the "
                "turn"
            )
