"""Provides the summary of field trials (`summary`): Table I's figures over a robot's walks
on one floor, as `linkevo hexapod simulate` prints them and a field trial logs them, with
what a builder should doubt in them (`caveats`)."""

from __future__ import annotations

import math
import statistics
from typing import TYPE_CHECKING

from linkevo.sim.robot.frailty import RANK
from linkevo.sim.robot.hexapod import Floor

if TYPE_CHECKING:
    from linkevo.sim.robot.walking import Walk

FOOT_DEVIATION_MM = 2.0
"""A foot further than this from where its linkage puts it is flagged (`caveats`): beyond
the loop closure a walk holds (`sim.robot.walking.LOOP_ERROR_BOUND_MM`); past
`sim.robot.breaks.INVALID_DEVIATION_MM` the walk is invalid."""
CHAOTIC_CM = 10.0
"""Repeats from hand-placed starts (heading ±3°, position ±5 mm, phases ±3°) whose
distances spread over more than this, and over more than `CHAOTIC_SHARE` of their mean
distance, walk a chaotic gait (`chaotic`): the robot's path hangs on how it was set down,
and one walk's distance says little of the next's. Sound walks of one leg agree within a
centimetre or two (docs/walking.md)."""
CHAOTIC_SHARE = 0.25
PITCH_CAVEAT_DEG = 20.0
"""A frame pitching further than this is flagged: the robot rocks, and how far it gets
depends on contacts the simulation models least well (`caveats`)."""


def summary(walks: list[Walk], floor: Floor, seconds: float) -> dict:
    """Returns the JSON-able summary of field trials: distances in cm per repeat and their
    mean, and the builder's figures over the repeats (means, or the worst where a limit
    matters)."""

    def worst(values) -> float | None:
        finite = [v for v in values if math.isfinite(v)]
        return max(finite) if finite else None

    def mean(values) -> float | None:
        finite = [v for v in values if math.isfinite(v)]
        return statistics.fmean(finite) if finite else None

    def least(values) -> float | None:
        finite = [v for v in values if math.isfinite(v)]
        return min(finite) if finite else None

    distances = [w.distance_m * 100 for w in walks]
    broken = [w.reason for w in walks if w.breaks]
    reason = f"{broken[0]} ({len(broken)} of {len(walks)} walks break)" if broken else ""
    bound = mean(w.bound_m for w in walks)
    return {
        "floor": floor.name,
        "seconds": seconds,
        "distance_cm": [None if not math.isfinite(v) else round(v, 2) for v in distances],
        "mean_distance_cm": rounded(mean(distances)),
        "bound_cm": None if bound is None else rounded(bound * 100),
        "heading_drift_deg": [round(w.heading_drift_deg, 2) for w in walks],
        "beyond_bound": any(w.distance_m > w.bound_m for w in walks if math.isfinite(w.distance_m)),
        "breaks": any(w.breaks for w in walks),
        "reason": reason,
        "body_height_cm": rounded(mean(w.body_height_m * 100 for w in walks)),
        "min_clearance_cm": rounded(least(w.clearance_m * 100 for w in walks)),
        "max_pitch_deg": rounded(worst(w.max_pitch_deg for w in walks)),
        "max_roll_deg": rounded(worst(w.max_roll_deg for w in walks)),
        "foot_slip_mm_s": rounded(mean(w.foot_slip_mm_s for w in walks)),
        "torque_p95_of_stall": rounded(worst(w.torque_p95 for w in walks), 3),
        "torque_max_of_stall": rounded(worst(w.torque_max for w in walks), 3),
        "max_lag_deg": rounded(worst(w.max_lag_deg for w in walks)),
        "pin_force_p50_n": rounded(mean(w.pin_force_n[0] for w in walks)),
        "pin_force_p95_n": rounded(mean(w.pin_force_n[1] for w in walks)),
        "pin_force_p99_n": rounded(worst(w.pin_force_n[2] for w in walks)),
        "pin_force_max_n": rounded(worst(w.pin_force_n[3] for w in walks)),
        "loop_error_max_mm": rounded(worst(w.loop_error_mm for w in walks), 3),
        "foot_deviation_max_mm": rounded(worst(w.foot_deviation_mm for w in walks), 3),
        "timestep_ms": [round(w.timestep * 1000, 3) for w in walks],
        "frame_contact_share": rounded(worst(w.frame_contact for w in walks), 3),
        "frailty": frailest(walks),
        "invalid": any(w.invalid for w in walks),
        "spacers": walks[0].spacers if walks else {},
        "chaotic": chaotic(walks),
        "caveats": caveats(walks),
    }


def frailest(walks: list[Walk]) -> dict | None:
    """Returns the frailty figures (`sim.robot.frailty.Frailty.as_dict`) of the walk whose leg
    gives most, or None when no walk has them (a walk that diverged)."""
    found = [w.frailty for w in walks if w.frailty is not None]
    if not found:
        return None
    return max(
        found, key=lambda f: (RANK[f.verdict], f.nominal.give_mm, f.nominal.axle_moment_nmm)
    ).as_dict()


def chaotic(walks: list[Walk]) -> bool:
    """Whether repeats of one robot from perturbed starts disagree widely: their distances
    spread over more than `CHAOTIC_CM` and `CHAOTIC_SHARE` of their mean's size."""
    distances = [w.distance_m * 100 for w in walks if math.isfinite(w.distance_m)]
    if len(distances) < 2:
        return False
    spread = max(distances) - min(distances)
    return spread > CHAOTIC_CM and spread > CHAOTIC_SHARE * abs(statistics.fmean(distances))


def caveats(walks: list[Walk]) -> list[str]:
    """Returns what a builder should know before trusting these walks' distances (empty
    when nothing): repeats that disagree widely (`chaotic`), a walk beyond the level-body
    no-slip bound, a frame that pitches past `PITCH_CAVEAT_DEG`, feet that stray past
    `FOOT_DEVIATION_MM` from their linkage's path."""
    out = []
    if chaotic(walks):
        distances = [w.distance_m * 100 for w in walks if math.isfinite(w.distance_m)]
        out.append(
            f"a chaotic gait: the repeats walk {min(distances):.0f} to {max(distances):.0f} cm "
            "from starts a few millimetres and degrees apart; one walk's distance says little "
            "of the next's"
        )
    beyond = [w for w in walks if math.isfinite(w.distance_m) and w.distance_m > w.bound_m]
    if beyond:
        out.append(
            f"{len(beyond)} of {len(walks)} walks go beyond the level-body bound "
            f"({beyond[0].bound_m * 100:.0f} cm): the robot slides or hops forwards, which a "
            "LEGO robot on a real floor may not"
        )
    pitch = max((w.max_pitch_deg for w in walks if math.isfinite(w.max_pitch_deg)), default=0.0)
    if pitch > PITCH_CAVEAT_DEG:
        out.append(
            f"the frame pitches up to {pitch:.0f}°: the robot rocks, and its distance "
            "rests on contacts the simulation models least well"
        )
    stray = max(
        (w.foot_deviation_mm for w in walks if math.isfinite(w.foot_deviation_mm)), default=0.0
    )
    if stray > FOOT_DEVIATION_MM:
        out.append(
            f"feet stray up to {stray:.1f} mm from their linkage's path (more than "
            f"{FOOT_DEVIATION_MM:g} mm)"
        )
    return out


def rounded(value: float | None, digits: int = 2) -> float | None:
    return None if value is None else round(float(value), digits)
