"""Real Technic parts for a leg (`sim.robot.parts`) and its LDraw model (`sim.robot.ldraw`),
checked against the LDraw library's own part files (`tests/data/ldraw`, CC BY 4.0): every
part exists there, every pin and axle sits in a hole of every beam it joins at the joint
within 0.1 mm, and no two beams of one layer overlap, on 50 study cells that real parts
build (`tests/data/study_cells.json`: cells of the paper-mode study grid's MAP-Elites F_p
repertoires)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from linkevo.sim.robot.ldraw import LDU, leg_ldr, robot_mpd
from linkevo.sim.robot.leg import recipe_and_leg
from linkevo.sim.robot.parts import catalogue, mounted_joints

DATA = Path(__file__).resolve().parents[1] / "data"
LIBRARY = DATA / "ldraw" / "parts"
HOLE = re.compile(r"^(beamhole|peghole|connhole|axlehol\d*|axlehole)\.dat$")
TOLERANCE_LDU = 0.25
"""0.1 mm."""


def read_lines(path: Path) -> list[list[str]]:
    return [line.split() for line in path.read_text(encoding="utf-8").splitlines() if line]


def placement(words: list[str]) -> tuple[np.ndarray, np.ndarray, str]:
    """A type-1 line's (offset (3,), rotation (3, 3), file)."""
    numbers = [float(v) for v in words[2:14]]
    return np.array(numbers[:3]), np.array(numbers[3:]).reshape(3, 3), words[14]


def hole_centres(number: str) -> np.ndarray:
    """(H, 3) the centres of a part's holes in its own coordinates, read from its LDraw file
    and its subparts (each hole's faces on either side of the beam count once)."""
    found = []

    def walk(path: Path, offset: np.ndarray, rotation: np.ndarray) -> None:
        for words in read_lines(path):
            if words[0] != "1":
                continue
            at, turn, name = placement(words)
            name = name.replace("\\", "/").lower()
            point, matrix = offset + rotation @ at, rotation @ turn
            if HOLE.match(name):
                found.append(point)
            elif name.startswith("s/"):
                walk(LIBRARY / name, point, matrix)

    walk(LIBRARY / f"{number}.dat", np.zeros(3), np.eye(3))
    centres = np.array(found)
    centres[:, 1] = 0.0  # a hole's faces lie at y = -10 and +10: its centre at y = 0
    return np.unique(np.round(centres, 3), axis=0)


@pytest.fixture(scope="module")
def built():
    """The 50 study cells' legs with their real parts and LDraw models."""
    cells = json.loads((DATA / "study_cells.json").read_text())
    out = []
    for cell in cells:
        recipe, leg = recipe_and_leg(np.array(cell["genome"]), cell["mode"])
        assert recipe.parts is not None, (cell["trial"], cell["cell"], recipe.note)
        out.append((recipe.parts, leg, leg_ldr(recipe.parts, leg, "test")))
    return out


def test_every_catalogue_part_is_an_ldraw_part_of_that_name():
    cat = catalogue()
    parts = (*cat.beams, *cat.pins, *cat.axles, *cat.bushes, cat.driver)
    for part in parts:
        title = (LIBRARY / f"{part.number}.dat").read_text(encoding="utf-8").splitlines()[0]
        assert " ".join(title.split()[1:]) == " ".join(part.name.split()), part.number
    for beam in cat.beams:  # the library's straight thick beams, and their holes
        assert len(hole_centres(beam.number)) == beam.size
    assert {b.size for b in cat.beams} == {1, 2, 3, 5, 7, 9, 11, 13, 15}
    assert max(p.size for p in cat.pins) == 3


def test_every_part_of_50_study_legs_exists_and_no_pin_is_longer_than_three_layers(built):
    assert len(built) == 50
    cat = catalogue()
    for _, _, text in built:
        for words in read_lines_of(text):
            if words[0] == "1":
                number = words[14].removesuffix(".dat")
                assert (LIBRARY / f"{number}.dat").exists(), number
                part = cat.part(number)
                assert part.kind != "pin" or part.size <= 3
                assert part.kind != "beam" or part.size in (1, 2, 3, 5, 7, 9, 11, 13, 15)


def read_lines_of(text: str) -> list[list[str]]:
    return [line.split() for line in text.splitlines() if line]


def test_every_pin_and_axle_sits_in_a_hole_of_every_beam_it_joins(built):
    cat = catalogue()
    for parts, leg, text in built:
        holes, fasteners = [], []
        for words in read_lines_of(text):
            if words[0] != "1":
                continue
            at, turn, name = placement(words)
            part = cat.part(name.removesuffix(".dat"))
            if part.kind in ("beam", "driver"):
                holes += [at + turn @ c for c in hole_centres(part.number)]
            elif part.kind in ("pin", "axle"):
                half = part.size * LDU / 2
                fasteners.append((at, turn @ np.array([1.0, 0.0, 0.0]), half, part))
        holes = np.array(holes)
        nodes = leg.paths[:, 0]
        for joint in mounted_joints(parts, 0):
            x, y = nodes[joint.node][0] * LDU, -nodes[joint.node][1] * LDU
            wanted = [np.array([x, y, layer * LDU]) for layer in joint.layers]
            for want in wanted:  # a beam's hole there, on each layer the joint joins
                assert np.linalg.norm(holes - want, axis=1).min() < TOLERANCE_LDU, joint

            passing = [f[3] for f in fasteners if passes_through(f, wanted)]
            assert passing == [joint.fastener], (joint, passing)


def passes_through(fastener, holes: list[np.ndarray]) -> bool:
    """Whether a pin or an axle (centre, axis, half length, part) passes every one of the
    holes' centres, each hole end to end."""
    centre, axis, half, _ = fastener
    off_axis = [np.linalg.norm(np.cross(h - centre, axis)) for h in holes]
    along = [abs(float((h - centre) @ axis)) + LDU / 2 for h in holes]
    return max(off_axis) < TOLERANCE_LDU and max(along) <= half + TOLERANCE_LDU


def test_no_two_beams_on_one_layer_overlap(built):
    cat = catalogue()
    for _, _, text in built:
        beams: dict[float, list[tuple[np.ndarray, np.ndarray]]] = {}
        for words in read_lines_of(text):
            if words[0] != "1":
                continue
            at, turn, name = placement(words)
            part = cat.part(name.removesuffix(".dat"))
            if part.kind == "beam" and part.size > 1:
                ends = [at + turn @ c for c in hole_centres(part.number)[[0, -1]]]
                beams.setdefault(round(at[2], 3), []).append(tuple(ends))
        for layer in beams.values():
            for i, (a0, a1) in enumerate(layer):
                for b0, b1 in layer[i + 1 :]:
                    assert segment_gap(a0, a1, b0, b1) >= 2 * 3.6 / 0.4 - TOLERANCE_LDU


def segment_gap(p1, p2, p3, p4) -> float:
    """The least distance between two segments, sampled densely."""
    t = np.linspace(0.0, 1.0, 401)[:, None]
    a, b = p1 + t * (p2 - p1), p3 + t * (p4 - p3)
    return float(np.linalg.norm(a[:, None] - b[None], axis=-1).min())


def test_the_robot_file_holds_six_legs_as_mounted(built):
    parts, leg, _ = built[0]
    phases = {"left-front": np.pi, "left-middle": 0.0, "left-rear": np.pi}
    phases |= {"right-front": 0.0, "right-middle": np.pi, "right-rear": 0.0}
    spacers = dict.fromkeys(phases, 0) | {"left-middle": 2, "right-middle": 2}
    text = robot_mpd(parts, leg, phases, spacers, spacing_ldu=400.0, side_ldu=180.0)
    files = re.findall(r"^0 FILE (\S+)$", text, flags=re.M)
    assert files[0] == "robot.ldr" and len(files) == 1 + 4  # two poses x two mountings
    references = [w for w in read_lines_of(text.split("0 NOFILE")[0]) if w[0] == "1"]
    assert len(references) == 6 and {w[14] for w in references} == set(files[1:])
    sides = {float(w[4]) > 0 for w in references}
    assert sides == {True, False}  # both sides, mirrored
    middle = [w for w in references if float(w[2]) == 0.0]
    assert {abs(float(w[4])) for w in middle} == {180.0 + 2 * LDU}
