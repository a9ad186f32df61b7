"""Benchmark: what the lean model's armature on the coupled parts does, in one run.

Run: `.venv/bin/python benchmarks/armature_effect.py --run-id RUN_ID [--tracking-uri URI]
[--cells 8]`: RUN_ID is a repertoire trial (the benchmark's: MAP-LIS/Fp/02 of the
paper-mode study grid). The same `--cells` buildable cells (every k-th by loss), as LEGO
legs, are walked 10 s on each floor with the walk-map walk (`sim.robot.walk_map.
walk_map_settings`) three ways: the lean model's armature as shipped
(`sim.robot.lean_model.CONTACT_INERTIA_KG` on each coupled part's slides, times (5 cm)^2 on its
hinge), a tenth of it, and none. Per leg it prints the armature's inertia reflected to the
crank through the leg's kinematics over the turn (mean and largest, against the motor's
rotor inertia at the crank, `sim.robot.hexapod.Motor.armature`), and per floor and setting the
distances' median and largest difference from the shipped setting, and the break verdicts
that change.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from linkevo.orchestrator.repertoire_walks import Selection
from linkevo.sim.robot import lean_model
from linkevo.sim.robot.hexapod import FLOORS, UNIT_M, Motor
from linkevo.sim.robot.leg import leg_from_genome
from linkevo.sim.robot.model import floor_reach
from linkevo.sim.robot.walk_map import walk_map_settings
from linkevo.sim.robot.walking import walk
from linkevo.workers.store.runs import RunStore

SHIPPED = lean_model.CONTACT_INERTIA_KG
SETTINGS = {"shipped": SHIPPED, "a tenth": SHIPPED / 10, "none": 0.0}


def reflected(leg, mass: float) -> np.ndarray:
    """Returns (A,) the armature of the coupled parts reflected to the crank (kg m^2) at
    each pose: per part, mass * |d pivot / d theta|^2 + mass * (5 cm)^2 * (d angle / d
    theta)^2, as `lean_model` couples them."""
    n = leg.paths.shape[1]
    dtheta = 2 * np.pi / n
    total = np.zeros(n)
    coupled = np.unique(leg.part[floor_reach(leg)])
    for part in coupled[coupled > 0]:  # the frame and the crank have no coupled slides
        members = np.flatnonzero(leg.part == part)
        pivot = int(leg.beams[members[0], 0])
        nodes = sorted({int(x) for b in members for x in leg.beams[b]} - {pivot})
        arms = [np.linalg.norm(leg.paths[x] - leg.paths[pivot], axis=1) for x in nodes]
        other = nodes[int(np.argmax([a.min() for a in arms]))]
        path = leg.paths[pivot] * UNIT_M
        velocity = (np.roll(path, -1, axis=0) - np.roll(path, 1, axis=0)) / (2 * dtheta)
        arm = leg.paths[other] - leg.paths[pivot]
        angle = np.unwrap(np.arctan2(arm[:, 1], arm[:, 0]))
        rate = np.gradient(angle, dtheta)
        total += mass * (velocity**2).sum(axis=1) + mass * 0.05**2 * rate**2
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run-id", required=True)
    parser.add_argument("--tracking-uri", default="sqlite:///runs/mlflow.db")
    parser.add_argument("--cells", type=int, default=8)
    args = parser.parse_args()
    store = RunStore.open(args.tracking_uri)
    trial = store.repertoire_trial(args.run_id)
    with tempfile.TemporaryDirectory() as tmp:
        table = store.repertoire(args.run_id, Path(tmp))
    chosen = Selection("buildable").choose(table, trial.mode)
    step = max(1, len(chosen) // args.cells)
    rotor = Motor().armature
    legs = []
    for genome in chosen["genome"].iloc[::step].head(args.cells):
        leg = leg_from_genome(np.asarray(genome, dtype=np.float64), trial.mode)
        if not leg.built:
            continue
        legs.append(leg)
        inertia = reflected(leg, SHIPPED)
        print(
            f"leg {len(legs)}: armature at the crank {inertia.mean() / rotor:.1%} of the "
            f"rotor's on average, {inertia.max() / rotor:.1%} at most"
        )
    settings = walk_map_settings()
    for floor in FLOORS:
        got = {}
        for name, mass in SETTINGS.items():
            lean_model.CONTACT_INERTIA_KG = mass
            got[name] = [walk(leg, FLOORS[floor], settings=settings) for leg in legs]
        lean_model.CONTACT_INERTIA_KG = SHIPPED
        base = got["shipped"]
        for name in ("a tenth", "none"):
            diff = [
                abs(a.distance_m - b.distance_m) * 100 for a, b in zip(got[name], base, strict=True)
            ]
            flips = sum(a.breaks != b.breaks for a, b in zip(got[name], base, strict=True))
            print(
                f"{floor}, {name} against shipped: distance difference median "
                f"{np.median(diff):.1f} cm, largest {max(diff):.1f} cm; {flips} of "
                f"{len(legs)} break verdicts change"
            )
        print(
            f"{floor}, shipped: distances "
            + ", ".join(f"{w.distance_m * 100:.0f}" for w in base)
            + " cm"
        )


if __name__ == "__main__":
    main()
