"""Provides a leg's LEGO build as an LDraw model (`leg_ldr`) and the robot's six legs as a
multi-part file (`robot_mpd`), in the format LDView, LeoCAD, LDCad and BrickLink Studio open.

LDraw units (LDU): a Technic module is 20 LDU; LDraw's y axis points down. The leg's plane
is the model's x-y plane (the linkage's x along x, its y up, so LDraw's -y), and its layers
go along +z, 20 LDU apart, layer 0 at z = 0 (the frame's side, and the motor's driver on
layer -1, towards -z). Each part is placed by its own geometry in the LDraw library
(`technic_parts.json`): a beam's holes lie along its z axis, 20 LDU apart and centred on its
middle hole, each hole's axis along its y; a pin's and an axle's axis is its x, centred;
a bush's axis is its z; the driver's axle hole is at its origin and its pin hole 20 LDU
along z. One `0 STEP` per layer builds the leg from the frame out.
"""

from __future__ import annotations

import math

import numpy as np

from linkevo.sim.robot.leg import Leg
from linkevo.sim.robot.parts import PartsBuild, Piece, catalogue, mounted_joints

LDU = 20.0
"""LDraw units per module (and per layer)."""
COLOUR_BEAM, COLOUR_PIN, COLOUR_AXLE = 71, 0, 7
"""LDraw colours: light bluish grey beams, black pins, light grey axles and bushes."""
ALONG_Z = (0, 0, -1, 0, 1, 0, 1, 0, 0)
"""A pin's or an axle's rotation: its x axis (the part's axis) along the model's z."""
UPRIGHT = (1, 0, 0, 0, 1, 0, 0, 0, 1)
"""A bush's rotation: its axis (z) is the model's z already."""


def _line(colour: int, at, rotation, file: str) -> str:
    """A type-1 line: a part (`file`) of a colour at a point (LDU) with a rotation (3 x 3,
    row by row)."""
    x, y, z = (_fmt(v) for v in at)
    return f"1 {colour} {x} {y} {z} " + " ".join(_fmt(v) for v in rotation) + f" {file}"


def _dat(part) -> str:
    return f"{part.number}.dat"


def _fmt(value: float) -> str:
    text = f"{float(value):.4f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _model(point: np.ndarray) -> np.ndarray:
    """(2,) a linkage point in modules -> its (x, y) in LDU (y down)."""
    return np.array([point[0] * LDU, -point[1] * LDU])


def _beam_rotation(direction: np.ndarray) -> tuple[float, ...]:
    """The rotation putting a beam's z axis along `direction` (2,) (model x-y, LDU) and
    its holes' axis (y) along the model's z."""
    ux, uy = direction / np.linalg.norm(direction)
    return (-uy, 0.0, ux, ux, 0.0, uy, 0.0, 1.0, 0.0)


def leg_lines(build: PartsBuild, leg: Leg, pose: int = 0, spacers: int = 0) -> list[str]:
    """Returns the LDraw lines of one leg at pose `pose` (an index into `Leg.paths`), its
    frame nodes' axles through `spacers` layers of bushes (`sim.robot.mounting`), one step
    per layer."""
    cat = catalogue()
    nodes = leg.paths[:, pose]  # (M, 2) modules
    by_layer: dict[int, list[str]] = {}

    def add(layer: float, colour: int, point, z: float, rotation, part) -> None:
        at = (*_model(point), z * LDU)
        by_layer.setdefault(math.floor(layer), []).append(_line(colour, at, rotation, _dat(part)))

    def along(beam: int, t: float) -> np.ndarray:
        s, e = leg.beams[beam]
        d = nodes[e] - nodes[s]
        return nodes[s] + t * d / np.linalg.norm(d)

    for piece in build.pieces:
        start, end = along(piece.beam, piece.t0), along(piece.beam, piece.t1)
        rotation = _beam_rotation(_model(end) - _model(start))
        add(piece.layer, COLOUR_BEAM, (start + end) / 2, piece.layer, rotation, piece.part)
    crank = build.pieces[0]
    layer = crank.layer - 1  # the driver, just inside the crank
    tip = along(crank.beam, 1.0)
    rotation = _beam_rotation(_model(tip) - _model(nodes[0]))
    add(layer, COLOUR_BEAM, nodes[0], layer, rotation, build.driver)
    add(crank.layer, COLOUR_PIN, tip, layer + 0.5, ALONG_Z, cat.pin(2, friction=True))
    for joint in mounted_joints(build, spacers):
        point = nodes[joint.node]
        low, high = joint.layers[0], joint.layers[-1]
        if joint.fastener.kind == "pin":
            add(high, COLOUR_PIN, point, (low + high) / 2, ALONG_Z, joint.fastener)
        else:
            add(high, COLOUR_AXLE, point, _axle_centre(joint), ALONG_Z, joint.fastener)
        for part, at in joint.fillers:
            if part.kind == "bush":
                add(at, COLOUR_AXLE, point, at, UPRIGHT, part)
            else:  # a one-hole beam
                add(at, COLOUR_BEAM, point, at, _beam_rotation(np.array([1.0, 0.0])), part)
    pieces_of: dict[int, list[Piece]] = {}
    for piece in build.pieces:
        pieces_of.setdefault(piece.bar, []).append(piece)
    for bar, t in build.locks:
        layers = sorted(p.layer for p in pieces_of[bar] if p.t0 <= t <= p.t1)
        point = along(pieces_of[bar][0].beam, t)
        add(layers[-1], COLOUR_PIN, point, (layers[0] + layers[-1]) / 2, ALONG_Z, cat.pin(2, True))
    lines = []
    for layer in sorted(by_layer):
        lines += [f"0 // layer {layer}", *by_layer[layer], "0 STEP"]
    return lines


def _axle_centre(joint) -> float:
    """Where an axle's middle lies, in layers: a frame node's runs from inside the frame
    (its grip) out to its outer beam's face (and past it to the half bush's); a moving
    joint's between its two half bushes."""
    high = joint.layers[-1]
    outer = high + 0.5 + (0.0 if joint.node == 0 else 0.5) if joint.frame else high + 1.0
    return outer - joint.fastener.size / 2


def leg_ldr(build: PartsBuild, leg: Leg, name: str, pose: int = 0) -> str:
    """Returns one leg at pose `pose` as an LDraw file (`leg.ldr`)."""
    head = [
        f"0 {name}",
        "0 Name: leg.ldr",
        "0 Author: linkevo",
        "0 // One leg at its first assembled crank angle, built from the frame out (a step",
        "0 // per layer). Parts from the LDraw library (CC BY 4.0).",
    ]
    return "\n".join(head + leg_lines(build, leg, pose)) + "\n"


def robot_mpd(
    build: PartsBuild,
    leg: Leg,
    phases: dict[str, float],
    spacers: dict[str, int],
    spacing_ldu: float,
    side_ldu: float,
) -> str:
    """Returns the six legs as an LDraw multi-part file (`robot.mpd`): a submodel per leg
    pose and spacers, each placed at its slot as the gait mounts it (left legs' layers
    outwards along +z, right legs mirrored, every leg facing the way its stance pushes).

    Args:
        phases: each slot's crank angle (radians); spacers: each slot's spacer layers.
        spacing_ldu: between neighbouring axles along the body; side_ldu: from the body's
            middle to a side's layer 0.
    """
    submodels: dict[tuple[int, int], str] = {}
    placements = []
    facing = leg.facing()
    for slot, phase in phases.items():
        pose = leg.pose_index(phase)
        key = (pose, spacers[slot])
        name = submodels.setdefault(
            key, f"leg-{round(math.degrees(phase)) % 360}deg-{spacers[slot]}spacers.ldr"
        )
        along = {"front": 1.0, "middle": 0.0, "rear": -1.0}[slot.split("-")[1]]
        side = 1.0 if slot.startswith("left") else -1.0
        out = side_ldu + spacers[slot] * LDU
        rotation = (-facing, 0, 0, 0, 1, 0, 0, 0, side)
        at = (along * spacing_ldu, 0.0, side * out)
        placements.append(f"0 // {slot}")
        placements.append(_line(16, at, rotation, name))
    lines = [
        "0 FILE robot.ldr",
        "0 linkevo hexapod: six legs on the study's frame",
        "0 Name: robot.ldr",
        "0 Author: linkevo",
        "0 // The frame (a printed box with the six motors) is not a LEGO part and is left out.",
        *placements,
        "0 NOFILE",
    ]
    for (pose, spacer), name in submodels.items():
        lines += [f"0 FILE {name}", f"0 {name}", f"0 Name: {name}", "0 Author: linkevo"]
        lines += leg_lines(build, leg, pose, spacer)
        lines.append("0 NOFILE")
    return "\n".join(lines) + "\n"
