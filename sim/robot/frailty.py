"""Provides `frailty`: how far a LEGO leg gives, how hard its beams and pins are loaded, and
whether that makes it frail, from the leg's own build and the loads of its walk, judged
with the uncertainty of what the figures rest on.

The walk's legs are rigid and planar; a LEGO leg is neither. Its beams sit on layers
(`sim.robot.layers`, `LAYER_PITCH_M` apart), so the foot, on its own layers, stands out of
the plane of the motor's axle and the robot's weight on it splays the leg sideways; a foot
that hangs on a beam past its last pin sags in the plane; and a pin joining beams on two
layers carries its in-plane force at an offset, a moment that bends it out of the plane.

The load is the robot's weight on the lone foot of a tripod (the middle foot, on its own on
one side, carries half of it, `foot_load_n`), through the stance (the lower half of the
foot's path), where the leg stands on it. Beam theory on a Technic liftarm's section along
the beam (`Section`) gives, at every stance pose:

- **sag** (in the plane): the beam the foot hangs on, as a cantilever from its last pin (from
  the axle for a foot on the crank's own part, one beam from the motor) loaded by the
  component of the load across it: a vertical give of `W l^3 cos^2(angle) / (3 E I_in)`;
- **splay** (out of the plane): the leg as a cantilever from the axle to the foot (its
  distance from the axle) bent by the end moment `W z`, z the offset of the layers the
  foot's beams take from the crank's, `M L^2 / (2 E I_out)`, plus the play of the pins on
  the way (`pin_play` per layer crossed, times that distance); splayed by s, the foot drops
  `s^2 / (2 L)`;
- **stress**: the larger of the sag's root moment and the splay's over the section
  (`M c / I`);
- **pin moment**: the walk's 99th-percentile pin force levered by the widest layer offset
  a pin of the leg bridges (all of it with the pin held at one end, half with it held at
  both);
- **axle moment**: the load on the motor's axle, held in the horn at the frame's side,
  levered by how far out the foot's layers sit (`Frame.leg_plane`, the leg's spacers,
  `sim.robot.mounting`, and its own layers).

Two kinds of limit, each argued in docs/walking.md ("Frail legs"): **stiffness**, the
foot's vertical give (sag and the splay's drop) against the step height it defeats, the
lift of its own path (`LIFT_SHARE`); **strength**, the stress against ABS's yield, the
pin moment against a Technic pin's bending yield and the axle moment against a cross
axle's. Every parameter has a range (`RANGES`),
and the verdict is three-valued: **frail** when a limit is passed even at the end of the
ranges most in the leg's favour, **sound** when none is at the end least in its favour,
**uncertain** in between, with the ranges printed. The walk itself stays rigid: the
figures say how far the real leg would give under the loads the rigid walk found, and a
frail leg (only) breaks the walk.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from linkevo.sim.robot.hexapod import LAYER_PITCH_M, UNIT_M, Frame
from linkevo.sim.robot.leg import Leg

if TYPE_CHECKING:
    from linkevo.sim.robot.mounting import Mounting
    from linkevo.sim.robot.walking import Walk

G = 9.81
SOUND, FRAIL, UNCERTAIN = "sound", "frail", "uncertain"
"""The three verdicts."""
LIFT_SHARE = 0.5
"""A stance foot that gives more than this share of its path's lift leaves the swinging
tripod clearing the floor by less than half the lift it was designed with: frail."""
SECTION_HALF_DEPTH_MM = {"in": 3.9, "out": 3.6}
"""The outer fibre's distance from the neutral axis: half the liftarm's 7.8 mm depth in the
plane, half its 7.2 mm thickness out of it."""


@dataclass(frozen=True)
class Section:
    """What the frailty figures rest on, each a value of its range (`RANGES`).

    Attributes:
        e_n_mm2: ABS's Young's modulus.
        i_in_mm4: a liftarm's second moment of area for bending in the leg's plane, along
            the beam (the solid between the holes and the counterbored holes in series).
        i_out_mm4: the same out of the leg's plane.
        pin_play_deg: a pin's tilt in its hole before it bears.
        yield_mpa: ABS's yield stress.
        pin_yield_nmm: the bending moment at which a Technic pin yields.
        pin_lever: the share of the widest layer offset a pin bridges that levers its
            force: 1 with the pin held at one end only, 0.5 held at both.
        axle_yield_nmm: the bending moment at which the motor's cross axle yields.
    """

    e_n_mm2: float
    i_in_mm4: float
    i_out_mm4: float
    pin_play_deg: float
    yield_mpa: float
    pin_yield_nmm: float
    pin_lever: float
    axle_yield_nmm: float


RANGES: dict[str, tuple[float, float, float]] = {
    "e_n_mm2": (2000.0, 2300.0, 2600.0),
    "i_in_mm4": (180.0, 200.0, 220.0),
    "i_out_mm4": (118.0, 124.0, 130.0),
    "pin_play_deg": (0.3, 0.5, 0.7),
    "yield_mpa": (35.0, 40.0, 45.0),
    "pin_yield_nmm": (350.0, 390.0, 430.0),
    "pin_lever": (0.5, 0.75, 1.0),
    "axle_yield_nmm": (300.0, 390.0, 490.0),
}
"""Each parameter's (low, nominal, high), from: ABS datasheets (E 2.0-2.6 GPa, tensile
yield 35-45 MPa); a liftarm 7.2 mm thick and 7.8-8.0 mm deep with 4.8 mm holes counterbored
to 6.2 mm, its section averaged along the beam (in the plane about 200 mm^4, out of it
118-130); a few tenths of a millimetre of radial play over a pin's 8 mm of engagement
(0.3-0.7°); a pin's 4.8 mm hollow shaft yielding at about 350-430 N·mm; a pin held by the
beams at both ends of its span (lever half the span) or at one end only (the whole span);
a cross axle's section (4.8 mm across, arms 1.8 mm: about 7.5 mm^3 of section modulus)
at the yield of the plastics axles are moulded from (40-65 MPa)."""
STIFFER = {
    "e_n_mm2": True,
    "i_in_mm4": True,
    "i_out_mm4": True,
    "pin_play_deg": False,
    "yield_mpa": True,
    "pin_yield_nmm": True,
    "pin_lever": False,
    "axle_yield_nmm": True,
}
"""Whether a higher value of each parameter is in a leg's favour."""


def _end(favour: bool) -> Section:
    """The section at the ends of the ranges most (`favour`) or least in a leg's favour."""
    pick = {k: RANGES[k][2] if up == favour else RANGES[k][0] for k, up in STIFFER.items()}
    return Section(**pick)


BEST, WORST = _end(True), _end(False)
NOMINAL = Section(**{k: v[1] for k, v in RANGES.items()})


@dataclass(frozen=True)
class Geometry:
    """What the leg's build and the load set, whatever the section (mm, N, degrees).

    Attributes:
        load_n: W, the load on the lone stance foot.
        lift_mm: the foot path's lift (its height over the turn).
        reach_mm: (S,) the foot's distance from the axle at each stance pose.
        offset_mm: z, the foot's layers' offset from the crank's.
        crossings: the layers a load crosses from the foot to the axle (pins with play).
        hang_mm: (S,) the length of the beam the foot hangs on past its last pin (0 where
            it does not hang), at each stance pose.
        hang_cos: (S,) the cosine of that beam's angle from the horizontal.
        bridged_mm: the widest layer offset a pin of the leg bridges.
        axle_mm: how far out from the frame's side the foot's layers sit (the lever of the
            load on the motor's axle).
    """

    load_n: float
    lift_mm: float
    reach_mm: np.ndarray
    offset_mm: float
    crossings: int
    hang_mm: np.ndarray
    hang_cos: np.ndarray
    bridged_mm: float
    axle_mm: float


@dataclass(frozen=True)
class Figures:
    """The frailty figures of one leg for one section (the worst stance pose of each)."""

    sag_mm: float
    splay_mm: float
    give_mm: float
    stress_mpa: float
    pin_moment_nmm: float
    axle_moment_nmm: float

    def limits_passed(self, geometry: Geometry, section: Section) -> list[str]:
        """Returns which limits these figures pass (empty when none)."""
        out = []
        if self.give_mm > LIFT_SHARE * geometry.lift_mm:
            out.append(
                f"the foot gives {self.give_mm:.1f} mm (sag {self.sag_mm:.1f}, splay "
                f"{self.splay_mm:.1f} mm) under the robot's weight, more than half its "
                f"{geometry.lift_mm:.0f} mm lift"
            )
        if self.stress_mpa > section.yield_mpa:
            out.append(
                f"a beam is stressed to {self.stress_mpa:.0f} MPa (ABS yields at "
                f"{section.yield_mpa:g})"
            )
        if self.pin_moment_nmm > section.pin_yield_nmm:
            out.append(
                f"a pin is bent out of the plane by {self.pin_moment_nmm:.0f} N·mm (a pin "
                f"yields at {section.pin_yield_nmm:g})"
            )
        if self.axle_moment_nmm > section.axle_yield_nmm:
            out.append(
                f"the motor's axle is bent by {self.axle_moment_nmm:.0f} N·mm, the leg "
                f"{geometry.axle_mm:.0f} mm out from the frame (an axle yields at "
                f"{section.axle_yield_nmm:g})"
            )
        return out


@dataclass(frozen=True)
class Frailty:
    """What makes one leg frail (`frailty`): the figures at the nominal section and at the
    ends of the ranges least and most in the leg's favour, and the verdict.

    Attributes:
        verdict: "sound", "frail" or "uncertain".
        geometry: what the build and the load set.
        nominal, best, worst: the figures at the nominal values, at the ends of the ranges
            most in the leg's favour and least.
    """

    verdict: str
    geometry: Geometry
    nominal: Figures
    best: Figures
    worst: Figures

    @property
    def frail(self) -> bool:
        """Whether the leg is frail for certain (the only verdict that breaks a walk)."""
        return self.verdict == FRAIL

    def reason(self) -> str:
        """The break reason in words ("" unless frail): the limits passed even at the ends
        of the ranges most in the leg's favour."""
        passed = self.best.limits_passed(self.geometry, BEST)
        return "frail: " + "; ".join(passed) if self.frail else ""

    def as_dict(self) -> dict:
        """The figures for a walk's JSON (`frailty`), rounded: each as [best, nominal,
        worst]."""

        def span(name: str, digits: int = 2) -> list[float]:
            return [round(getattr(f, name), digits) for f in (self.best, self.nominal, self.worst)]

        return {
            "verdict": self.verdict,
            "give_mm": span("give_mm"),
            "lift_mm": round(self.geometry.lift_mm, 1),
            "sag_mm": span("sag_mm"),
            "splay_mm": span("splay_mm"),
            "stress_mpa": span("stress_mpa", 1),
            "pin_moment_nmm": span("pin_moment_nmm", 1),
            "axle_moment_nmm": span("axle_moment_nmm", 1),
            "axle_mm": round(self.geometry.axle_mm, 1),
            "foot_load_n": round(self.geometry.load_n, 2),
            "frail": self.frail,
            "limits_passed": self.worst.limits_passed(self.geometry, WORST),
        }


def cantilever_tip_load_mm(load_n: float, length_mm: float, e: float, i_mm4: float) -> float:
    """Returns the tip deflection of a cantilever under a tip load: `F L^3 / (3 E I)`."""
    return load_n * length_mm**3 / (3.0 * e * i_mm4)


def cantilever_end_moment_mm(moment_nmm: float, length_mm: float, e: float, i_mm4: float) -> float:
    """Returns the tip deflection of a cantilever under an end moment: `M L^2 / (2 E I)`."""
    return moment_nmm * length_mm**2 / (2.0 * e * i_mm4)


def foot_load_n(frame: Frame, leg: Leg) -> float:
    """Returns W: the robot's weight (frame and six legs' beams) on the lone foot of a
    tripod: the middle foot, alone on its side, carries half of it (the front and rear feet
    of the other side a quarter each), with the body's weight centred."""
    legs_kg = 6 * float(leg.piece_kg.sum())
    return (frame.mass_kg + legs_kg) * G / 2.0


def geometry(leg: Leg, frame: Frame | None = None, spacer: int = 0) -> Geometry:
    """Returns what the leg's build, `spacer` layers out from the frame, and its walk's loads
    set (`Geometry`)."""
    frame = frame or Frame()
    unit_mm, pitch_mm = UNIT_M * 1000.0, LAYER_PITCH_M * 1000.0
    motor = int(leg.frame_nodes[0])
    path = leg.foot_path()
    y = path[:, 1]
    stance = np.flatnonzero(y <= (y.min() + y.max()) / 2)
    reach = np.linalg.norm(path[stance] - leg.paths[motor, 0], axis=1) * unit_mm
    foot_beams = np.flatnonzero((leg.beams == leg.foot).any(axis=1))
    crank_layer = int(leg.layer[0])
    foot_layers = leg.layer[foot_beams] if foot_beams.size else np.array([crank_layer])
    offset = abs(float(foot_layers.mean()) - crank_layer) * pitch_mm
    crossings = len(set(leg.layer.tolist())) - 1
    hang = np.zeros(len(stance))
    cos = np.zeros(len(stance))
    if foot_beams.size == 1:  # the foot hangs on this beam alone: a cantilever
        b = int(foot_beams[0])
        start, end = leg.beams[b]
        pinned = int(start if end == leg.foot else end)
        if leg.part[b] == 0:  # on the crank's own part: one beam from the axle
            pinned = motor
        arm = leg.paths[leg.foot][stance] - leg.paths[pinned][stance]  # (S, 2) modules
        hang = np.linalg.norm(arm, axis=1) * unit_mm
        cos = np.abs(arm[:, 0]) / np.maximum(np.linalg.norm(arm, axis=1), 1e-12)
    bridged = 0
    for node in range(leg.paths.shape[0]):
        layers = leg.layer[(leg.beams == node).any(axis=1)]
        if layers.size >= 2:
            bridged = max(bridged, int(layers.max() - layers.min()))
    return Geometry(
        load_n=foot_load_n(frame, leg),
        lift_mm=float(np.ptp(y)) * unit_mm,
        reach_mm=reach,
        offset_mm=offset,
        crossings=crossings,
        hang_mm=hang,
        hang_cos=cos,
        bridged_mm=bridged * pitch_mm,
        axle_mm=frame.leg_plane * 1000.0 + (spacer + float(foot_layers.mean())) * pitch_mm,
    )


def figures(g: Geometry, s: Section, pin_force_p99_n: float) -> Figures:
    """Returns the frailty figures of a leg's geometry for one section."""
    w = g.load_n
    sag = cantilever_tip_load_mm(w, 1.0, s.e_n_mm2, s.i_in_mm4) * g.hang_mm**3 * g.hang_cos**2
    bend = cantilever_end_moment_mm(w * g.offset_mm, 1.0, s.e_n_mm2, s.i_out_mm4) * g.reach_mm**2
    splay = bend + g.crossings * math.radians(s.pin_play_deg) * g.reach_mm
    drop = splay**2 / (2.0 * np.maximum(g.reach_mm, 1e-9))
    give = sag + drop
    worst = int(np.argmax(give))
    stress = max(
        float(np.max(w * g.hang_cos * g.hang_mm)) * SECTION_HALF_DEPTH_MM["in"] / s.i_in_mm4,
        w * g.offset_mm * SECTION_HALF_DEPTH_MM["out"] / s.i_out_mm4,
    )
    return Figures(
        sag_mm=float(sag[worst]),
        splay_mm=float(splay[worst]),
        give_mm=float(give[worst]),
        stress_mpa=stress,
        pin_moment_nmm=pin_force_p99_n * g.bridged_mm * s.pin_lever,
        axle_moment_nmm=w * g.axle_mm,
    )


def frailty(
    leg: Leg, pin_force_p99_n: float, frame: Frame | None = None, spacer: int = 0
) -> Frailty:
    """Returns the leg's frailty under its walk's loads (module docstring).

    Args:
        leg: the leg as walked (its layers, its nodes' paths in modules).
        pin_force_p99_n: the walk's 99th-percentile pin force (`Walk.pin_force_n[2]`).
        frame: the chassis (its mass loads the feet; default: the study's robot).
        spacer: the spacer layers between the frame and the leg (`sim.robot.mounting`).
    """
    g = geometry(leg, frame, spacer)
    best, nominal, worst = (figures(g, s, pin_force_p99_n) for s in (BEST, NOMINAL, WORST))
    if best.limits_passed(g, BEST):
        verdict = FRAIL
    elif worst.limits_passed(g, WORST):
        verdict = UNCERTAIN
    else:
        verdict = SOUND
    return Frailty(verdict, g, nominal, best, worst)


RANK = {SOUND: 0, UNCERTAIN: 1, FRAIL: 2}


def judge_frailty(result: Walk, mounting: Mounting) -> Walk:
    """Returns the walk with its legs' frailty as mounted (the frailest leg) and, for a frail
    leg, "frail" among its break reasons."""
    if result.diverged or result.invalid:  # no loads to judge a leg by
        return result
    distinct = {(id(mounting.legs[s]), mounting.spacers[s]): s for s in mounting.legs}.values()
    p99 = result.pin_force_n[2]
    found = [frailty(mounting.legs[s], p99, mounting.frame, mounting.spacers[s]) for s in distinct]
    worst = max(
        found,
        key=lambda f: (
            RANK[f.verdict],
            f.nominal.give_mm,
            f.nominal.pin_moment_nmm,
            f.nominal.axle_moment_nmm,
        ),
    )
    reason = "; ".join(r for r in (result.reason, worst.reason()) if r)
    return dataclasses.replace(result, frailty=worst, breaks=bool(reason), reason=reason)
