"""Provides `frailty`: how far a LEGO leg bends and how hard its pins are levered out of
the leg's plane, from the leg's own build and the loads of its walk.

The walk's legs are rigid and planar; a LEGO leg is neither. Its beams sit on layers
(`sim.robot.layers`, `LAYER_PITCH_M` apart), so a pin joining beams on two layers carries its
in-plane force at an offset, a moment out of the plane that bends the pin and levers a
friction pin out of its hole; and the foot, on its own layer, stands out of the plane of
the motor's axle, so the robot's weight on it splays the leg sideways. Beam theory on a
Technic beam's section (`ABS_E_N_MM2`, `I_OUT_MM4`, `I_IN_MM4`) gives the deflections:

- **splay** (out of the plane): the leg as a cantilever from the axle to the foot (length
  `reach`, the foot's largest distance from the axle over the turn) bent by the end moment
  `W * z` (the foot's load W at the foot layer's offset z from the crank's layer):
  `M L^2 / (2 E I_out)`, plus the play of the friction pins on the way (`PIN_PLAY_RAD`
  per layer crossed, times the reach);
- **sag** (in the plane): the foot's beam, where it is an extension cantilevered past its
  last pin, bent by W at its tip: `W l^3 / (3 E I_in)`;
- **pin moment**: the walk's 99th-percentile pin force times the largest layer offset a
  pin of the leg bridges.

W is the robot's weight over one tripod's three feet (`foot_load_n`). The figures are
static estimates, the walk itself stays rigid: they say how far the real leg would give
under the loads the rigid walk found, and `FRAIL_FOOT_MM` / `FRAIL_PIN_MOMENT_NMM` decide
when that is too far (a "frail" break reason of the walk, `judge_frailty`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from linkevo.sim.robot.hexapod import BEAM_KG_PER_MODULE, LAYER_PITCH_M, UNIT_M, Frame
from linkevo.sim.robot.leg import Leg

if TYPE_CHECKING:
    from linkevo.sim.robot.walking import Walk

ABS_E_N_MM2 = 2300.0
"""Young's modulus of ABS, the Technic beam's plastic (2.0-2.4 GPa in datasheets)."""
BEAM_MM = 7.2
"""A Technic beam's section is 7.2 mm square."""
HOLE_MM = 4.8
"""Its pin holes, one per module, 4.8 mm across, through the beam's thickness."""
I_IN_MM4 = BEAM_MM * (BEAM_MM**3 - HOLE_MM**3) / 12.0
"""Second moment of area for bending in the leg's plane, through a hole (the weakest
section): the 7.2 mm depth less the hole, 7.2 mm thick: about 158 mm^4."""
I_OUT_MM4 = (BEAM_MM - HOLE_MM) * BEAM_MM**3 / 12.0
"""For bending out of the leg's plane, through a hole: the two 1.2 mm walls beside the hole,
7.2 mm deep: about 75 mm^4."""
PIN_PLAY_RAD = np.deg2rad(0.5)
"""A friction pin's tilt in its hole before it bears (about 0.07 mm of radial play over
its 8 mm of engagement)."""
FRAIL_FOOT_MM = 24.0
"""A foot that gives more than three modules (24 mm, about the lift of the study's foot
paths) under the robot's weight folds under the frame instead of lifting it. The splay is
a worst case (the whole leg bending as one beam, every pin's play adding up; a real leg's
beams share the load), so the limit is set where even a leg several times stiffer gives
more than a module."""
FRAIL_PIN_MOMENT_NMM = 1920.0
"""The out-of-plane moment on a pin above which the leg is frail: the in-plane pin-load
limit (60 N, `sim.robot.breaks.PIN_FORCE_LIMIT_N`) levered across four layers (32 mm), the
widest bridge a two-pin Technic connector spans."""
G = 9.81


@dataclass(frozen=True)
class Frailty:
    """What makes one leg frail (`frailty`).

    Attributes:
        foot_load_n: W, the load on one stance foot.
        reach_mm: the foot's largest distance from the motor axle over the turn.
        foot_layer_offset_mm: the foot's beam's layer offset from the crank's.
        splay_mm: the foot's deflection out of the leg's plane (bending and pin play).
        sag_mm: the foot's deflection in the plane (its cantilevered extension bending).
        foot_deflection_mm: the two combined (root of the sum of squares).
        pin_moment_nmm: the largest out-of-plane moment on a pin (the walk's 99th-
            percentile pin force at the largest layer offset a pin bridges).
    """

    foot_load_n: float
    reach_mm: float
    foot_layer_offset_mm: float
    splay_mm: float
    sag_mm: float
    foot_deflection_mm: float
    pin_moment_nmm: float

    @property
    def frail(self) -> bool:
        """Whether the leg gives or levers its pins beyond the limits."""
        return self.foot_deflection_mm > FRAIL_FOOT_MM or self.pin_moment_nmm > FRAIL_PIN_MOMENT_NMM

    def reason(self) -> str:
        """The break reason in words ("" when not frail)."""
        parts = []
        if self.foot_deflection_mm > FRAIL_FOOT_MM:
            parts.append(
                f"the foot gives {self.foot_deflection_mm:.1f} mm under the robot's weight "
                f"(splay {self.splay_mm:.1f}, sag {self.sag_mm:.1f}; above {FRAIL_FOOT_MM:g} mm)"
            )
        if self.pin_moment_nmm > FRAIL_PIN_MOMENT_NMM:
            parts.append(
                f"a pin is levered out of the plane by {self.pin_moment_nmm:.0f} N·mm (above "
                f"{FRAIL_PIN_MOMENT_NMM:g})"
            )
        return "frail: " + "; ".join(parts) if parts else ""

    def as_dict(self) -> dict[str, float]:
        """The figures for a walk's JSON (`frailty`), rounded."""
        return {
            "foot_deflection_mm": round(self.foot_deflection_mm, 2),
            "splay_mm": round(self.splay_mm, 2),
            "sag_mm": round(self.sag_mm, 2),
            "pin_moment_nmm": round(self.pin_moment_nmm, 1),
            "foot_load_n": round(self.foot_load_n, 2),
            "frail": self.frail,
        }


def cantilever_tip_load_mm(load_n: float, length_mm: float, i_mm4: float) -> float:
    """Returns the tip deflection of a cantilever under a tip load: `F L^3 / (3 E I)`."""
    return load_n * length_mm**3 / (3.0 * ABS_E_N_MM2 * i_mm4)


def cantilever_end_moment_mm(moment_nmm: float, length_mm: float, i_mm4: float) -> float:
    """Returns the tip deflection of a cantilever under an end moment: `M L^2 / (2 E I)`."""
    return moment_nmm * length_mm**2 / (2.0 * ABS_E_N_MM2 * i_mm4)


def foot_load_n(frame: Frame, leg: Leg) -> float:
    """Returns W: the robot's weight (frame and six legs' beams) over one tripod's feet."""
    lengths = np.linalg.norm(leg.paths[leg.beams[:, 1], 0] - leg.paths[leg.beams[:, 0], 0], axis=1)
    legs_kg = 6 * BEAM_KG_PER_MODULE * float(lengths.sum())
    return (frame.mass_kg + legs_kg) * G / 3.0


def frailty(leg: Leg, pin_force_p99_n: float, frame: Frame | None = None) -> Frailty:
    """Returns the leg's frailty under its walk's loads (module docstring).

    Args:
        leg: the leg as walked (its layers, its nodes' paths in modules).
        pin_force_p99_n: the walk's 99th-percentile pin force (`Walk.pin_force_n[2]`).
        frame: the chassis (its mass loads the feet; default: the study's robot).
    """
    frame = frame or Frame()
    unit_mm, pitch_mm = UNIT_M * 1000.0, LAYER_PITCH_M * 1000.0
    load = foot_load_n(frame, leg)
    motor = leg.frame_nodes[0]
    reach = float(np.linalg.norm(leg.paths[leg.foot] - leg.paths[motor], axis=1).max()) * unit_mm
    foot_beams = np.flatnonzero((leg.beams == leg.foot).any(axis=1))
    crank_layer = int(leg.layer[0])
    foot_layer = int(leg.layer[foot_beams].max()) if foot_beams.size else crank_layer
    offset = abs(foot_layer - crank_layer) * pitch_mm
    crossings = len(set(leg.layer.tolist())) - 1
    splay = cantilever_end_moment_mm(load * offset, reach, I_OUT_MM4) + (
        crossings * PIN_PLAY_RAD * reach
    )
    sag = 0.0
    for b in foot_beams:
        start, end = leg.beams[b]
        pinned = start if end == leg.foot else end
        shared = int(((leg.beams == pinned).any(axis=1)).sum())
        foot_pins = int(((leg.beams == leg.foot).any(axis=1)).sum())
        if foot_pins == 1 and shared >= 2:  # the foot hangs on this beam alone: a cantilever
            length = float(np.linalg.norm(leg.paths[leg.foot, 0] - leg.paths[pinned, 0])) * unit_mm
            sag = max(sag, cantilever_tip_load_mm(load, length, I_IN_MM4))
    bridged = 0
    for node in range(leg.paths.shape[0]):
        layers = leg.layer[(leg.beams == node).any(axis=1)]
        if layers.size >= 2:
            bridged = max(bridged, int(layers.max() - layers.min()))
    return Frailty(
        foot_load_n=load,
        reach_mm=reach,
        foot_layer_offset_mm=offset,
        splay_mm=splay,
        sag_mm=sag,
        foot_deflection_mm=float(np.hypot(splay, sag)),
        pin_moment_nmm=pin_force_p99_n * bridged * pitch_mm,
    )


def judge_frailty(result: Walk, legs: dict[str, Leg], frame: Frame) -> Walk:
    """Returns the walk with its legs' frailty (`sim.robot.frailty`, the frailest leg) and, for a
    frail leg, "frail" among its break reasons."""
    if result.diverged:
        return result
    distinct = {id(leg): leg for leg in legs.values()}.values()
    found = [frailty(leg, result.pin_force_n[2], frame) for leg in distinct]
    worst = max(found, key=lambda f: (f.frail, f.foot_deflection_mm, f.pin_moment_nmm))
    reason = "; ".join(r for r in (result.reason, worst.reason()) if r)
    return dataclasses.replace(result, frailty=worst, breaks=bool(reason), reason=reason)
