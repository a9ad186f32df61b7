"""Provides how the legs are mounted on the frame: the layers of spacer between the frame and
each leg (`auto_spacers`, chosen as a builder would so that neighbouring legs cannot meet)
and the check that neighbouring legs strike each other as they turn (`Mounting.strike`).

The three legs of a side turn in one plane, `Frame.leg_spacing` apart along the body; a leg
wider than the spacing sweeps into its neighbour's. A builder mounts such neighbours apart:
one of them sits further out on spacers (bushes on the motor's axle, a layer each), so that
no beam of one shares a layer with a beam of the other that it comes near over the turn (each
beam as built, `sim.robot.leg.Leg.pieces`).
Each spacer layer moves the leg's load further along the axle (`sim.robot.frailty`, the
axle's moment).

The check is kinematic: two legs of a side touch when a beam of one comes within a beam's
width of a beam of the other on a layer both occupy, their poses taken at the crank angles
the legs reach together (their phases apart as the gait sets them, or as a walk turned
them). Beams of different legs never collide in the physics (`sim.robot.model`), so a
walk whose legs touch is broken by this check, naming the two legs.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from linkevo.sim.robot.hexapod import BEAM_RADIUS_M, LEG_SLOTS, UNIT_M, Frame, Robot
from linkevo.sim.robot.layers import segment_distance
from linkevo.sim.robot.leg import Leg

SIDES: tuple[str, str] = ("left", "right")
ALONG = {"front": 1.0, "middle": 0.0, "rear": -1.0}
"""Where a slot's axle sits along the body, in leg spacings from the middle."""
SWEEP_ANGLES = 120
"""Crank angles at which two legs' sweeps are compared over a turn (three degrees apart, as a
walk's control ticks are)."""
TOUCH_MODULES = 2 * BEAM_RADIUS_M / UNIT_M
"""Two beams closer than a beam's width (centre line to centre line) touch."""
CLEARANCE_MODULES = TOUCH_MODULES + 0.5
"""Beams of neighbouring legs that come closer than this (half a module, 4 mm, of clearance
between them: the sampling of the turn, the legs' lag behind their phases) are put on
different layers (`auto_spacers`)."""


@dataclass(frozen=True)
class Mounting:
    """Six legs as mounted on a frame.

    Attributes:
        legs: the leg in each slot (`sim.robot.hexapod.LEG_SLOTS`).
        spacers: each slot's spacer layers between the frame and its leg.
        frame: the chassis (its leg spacing).
    """

    legs: dict[str, Leg]
    spacers: dict[str, int]
    frame: Frame

    def layers(self, slot: str) -> set[int]:
        """The layers the slot's leg occupies, counted from the frame, spacers included."""
        leg = self.legs[slot]
        return set((leg.piece_layer + self.spacers[slot]).tolist())

    def strikes(self, phases: np.ndarray) -> list[tuple[str, str, int]]:
        """Returns the neighbouring legs that touch: (slot, slot, the first instant), for
        each pair of a side whose beams touch on a shared layer.

        Args:
            phases: (T, 6) each slot's crank angle (radians, `LEG_SLOTS` order) at T
                instants.
        """
        out = []
        for a, b in pairs():
            if not self.layers(a) & self.layers(b):
                continue
            poses = [self.legs[s].pose_index(phases[:, LEG_SLOTS.index(s)]) for s in (a, b)]
            la, lb = (self.legs[s].piece_layer + self.spacers[s] for s in (a, b))
            touch = near((self.legs[a], self.legs[b]), (a, b), poses, self.spacing)
            touch &= la[None, :, None] == lb[None, None, :]
            hits = touch.any(axis=(1, 2))
            if hits.any():
                out.append((a, b, int(np.argmax(hits))))
        return out

    def strike(self, t: np.ndarray, phases: np.ndarray) -> str:
        """Returns the break reason of legs that strike each other over a walk ("" when
        none do), naming the first pair and when; arguments (T,) and (T, 6) as `strikes`."""
        found = self.strikes(phases)
        if not found:
            return ""
        a, b, first = min(found, key=lambda hit: hit[2])
        return (
            f"the {a} and {b} legs strike each other ({float(t[first] - t[0]):.1f} s in): their "
            "beams meet on a layer both take; mount them apart (spacers, docs/walking.md)"
        )

    @property
    def spacing(self) -> float:
        """The leg spacing in modules."""
        return self.frame.leg_spacing / UNIT_M


def pairs() -> list[tuple[str, str]]:
    """Each side's pairs of slots, front to rear."""
    out = []
    for side in SIDES:
        out += itertools.combinations([s for s in LEG_SLOTS if s.startswith(side)], 2)
    return out


def near(
    legs: tuple[Leg, Leg],
    slots: tuple[str, str],
    poses: list[np.ndarray],
    spacing: float,
    within: float = TOUCH_MODULES,
) -> np.ndarray:
    """Returns (K, Ba, Bb) whether each beam of one leg comes within `within` modules of each
    beam of the other in the side's plane, at each of K instants, whatever their layers.

    Args:
        legs, slots: two legs of a side and their slots.
        poses: each leg's pose index (K,) at the same K instants.
        spacing: the leg spacing in modules.
    """
    a = _segments(legs[0], slots[0], poses[0], spacing)  # (K, Ba, 2, 2)
    b = _segments(legs[1], slots[1], poses[1], spacing)
    a, b = a[:, :, None], b[:, None, :]
    return segment_distance(a[..., 0, :], a[..., 1, :], b[..., 0, :], b[..., 1, :]) < within


def auto_spacers(
    legs: dict[str, Leg], phases: dict[str, float], spacing_m: float
) -> dict[str, int]:
    """Returns each slot's spacer layers as a builder would choose them: for each leg of a
    side, front to rear, the fewest that keep every beam that comes near a beam of an
    earlier leg over a turn (at their phases, within `CLEARANCE_MODULES`) off that beam's
    layer, up to the leg's `most_spacers` (past them the legs strike: `Mounting.strikes`).
    Legs whose sweeps never meet get none.

    Args:
        legs: the leg in each slot; phases: each slot's phase offset (radians).
        spacing_m: the frame's leg spacing.
    """
    spacing = spacing_m / UNIT_M
    turn = np.arange(SWEEP_ANGLES) * 2 * math.pi / SWEEP_ANGLES
    out: dict[str, int] = {}
    for side in SIDES:
        slots = [s for s in LEG_SLOTS if s.startswith(side)]
        for k, slot in enumerate(slots):
            meeting = []  # (earlier leg's beam layers, this leg's, the pairs that meet)
            for e in slots[:k]:
                poses = [legs[s].pose_index(turn + phases[s]) for s in (e, slot)]
                close = near((legs[e], legs[slot]), (e, slot), poses, spacing, CLEARANCE_MODULES)
                if close.any():
                    layers = (legs[e].piece_layer + out[e], legs[slot].piece_layer)
                    meeting.append((*layers, close.any(axis=0)))
            spacer = 0
            while spacer < legs[slot].most_spacers and any(
                (m & (a[:, None] == b[None, :] + spacer)).any() for a, b, m in meeting
            ):
                spacer += 1
            out[slot] = spacer
    return out


def robot_spacers(leg: Leg, robot: Robot | None = None) -> dict[str, int]:
    """Returns each slot's spacer layers for a robot with this leg in every slot: the
    robot's own `[mounting]`, else `auto_spacers` at its phases on its frame (default: the
    study's robot)."""
    robot = robot or Robot()
    if robot.spacers is not None:
        return dict(robot.spacers)
    phases = {s: math.radians(v) for s, v in robot.phases_deg.items()}
    return auto_spacers(dict.fromkeys(LEG_SLOTS, leg), phases, robot.physics.leg_spacing_m)


def spacers_text(spacers: dict[str, int]) -> str:
    """Returns the spacers in words: "none" or "left-middle 3, right-middle 3 (others
    none)"."""
    spaced = [f"{slot} {n}" for slot, n in spacers.items() if n]
    if not spaced:
        return "none"
    return ", ".join(spaced) + (" (others none)" if len(spaced) < len(spacers) else "")


def _segments(leg: Leg, slot: str, poses: np.ndarray, spacing: float) -> np.ndarray:
    """Returns (K, P, 2, 2) each piece's end holes (`Leg.pieces`) at K pose indices in the
    side's plane (x along the body, y up; modules), the leg's axle placed by its slot and
    facing as mounted."""
    axle = ALONG[slot.split("-")[1]] * spacing
    ends = leg.piece_ends(poses)  # (P, K, 2, 2)
    plane = np.stack([axle - leg.facing() * ends[..., 0], ends[..., 1]], axis=-1)
    return plane.transpose(1, 0, 2, 3)
