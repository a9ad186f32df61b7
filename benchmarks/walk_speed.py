"""Benchmark: how fast the 3-D walk runs on one core, against MuJoCo's own ceiling.

Run: `.venv/bin/python benchmarks/walk_speed.py` (options: --linkage FILE.json, --seconds,
--repeats, --floor). The robot is the study's hexapod on six copies of a linkage: by
default `benchmarks/walk_linkage.json`, the first robot of MAP-LIS in the paper-mode study
grid (`linkevo hexapod study`). The process is pinned to one core.

Per floor and robot model (`sim.robot.walking.MODELS`: `lean`, the default, and `full`), each the
best of `--repeats` runs, simulated seconds per wall second:
- **walk**: `sim.robot.walking.walk` as `linkevo hexapod simulate` runs it: model built, settled,
  then the gait's controller, the motors and the records a builder reads (pin statics
  included);
- **ceiling**: the same model stepped for the same time in control ticks with constant
  motor goals, nothing recorded (what MuJoCo itself allows; the lean model's couplings are
  re-centred each tick, without which it cannot turn).
The distance each model walks is printed beside, and the lean walk's speed over the full
walk's is the ratio against today's code. Goal: walk >= 20x real time (a 10-s trial in
<= 0.5 s).

With `--against TREE` (another checkout, `git worktree add ../base REV`) it times instead
the walk of each floor and model as this tree's code and as TREE's runs it, in separate
processes taking turns, and prints each tree's best time and the ratio (the same walk:
the distances agree).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np

from linkevo.sim.linkage.linkage_doc import from_document
from linkevo.sim.robot.hexapod import FLOORS, LEG_SLOTS, TRIPOD_OFFSETS_DEG
from linkevo.sim.robot.leg import leg_from_genome
from linkevo.sim.robot.walking import MODELS, WalkSettings, walk

DEFAULT_LINKAGE = Path(__file__).with_name("walk_linkage.json")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--linkage", type=Path, default=DEFAULT_LINKAGE)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--floor", nargs="+", default=list(FLOORS))
    parser.add_argument("--against", type=Path, default=None, help="another checkout to time")
    args = parser.parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    if args.against is not None:
        against(args)
        return
    genome, mode = from_document(json.loads(args.linkage.read_text(encoding="utf-8")))
    leg = leg_from_genome(genome, mode)
    print(
        f"{platform.processor() or platform.machine()}, mujoco {mujoco.__version__}, one core; "
        f"leg {args.linkage.name}: {leg.n_parts} moving parts, {len(leg.beams)} beams"
    )
    figures = {}
    for name in args.floor:
        floor = FLOORS[name]
        for model in MODELS:
            settings = WalkSettings(seconds=args.seconds, model=model)
            simulated = settings.seconds + settings.settle_s
            walks = []
            walk_s = min(
                _timed(lambda f=floor, s=settings, w=walks: w.append(walk(leg, f, settings=s)))
                for _ in range(args.repeats)
            )
            build = MODELS[model][0]
            robot = build(
                dict.fromkeys(LEG_SLOTS, leg),
                {s: np.radians(TRIPOD_OFFSETS_DEG[s]) for s in LEG_SLOTS},
                floor,
                timestep=settings.step,
            )
            ticks = round(simulated * 50)
            ceiling_s = min(
                _timed(lambda r=robot, n=ticks: _bare(r, n)) for _ in range(args.repeats)
            )
            figures[f"{name}/{model}"] = {
                "walk_x_real_time": round(simulated / walk_s, 1),
                "ceiling_x_real_time": round(simulated / ceiling_s, 1),
                "walk_s_per_10s_trial": round(walk_s * 10.0 / args.seconds, 3),
                "share_of_ceiling": round(ceiling_s / walk_s, 3),
                "distance_cm": round(walks[-1].distance_m * 100, 1),
                "bodies": int(robot.model.nbody),
                "dofs": int(robot.model.nv),
                "equalities": int(robot.model.neq),
                "timestep_ms": settings.step * 1000,
            }
            print(
                f"{name:>6} {model:>4}: walk {simulated / walk_s:5.1f}x real time "
                f"({walk_s:.3f} s for {simulated:g} simulated s); ceiling "
                f"{simulated / ceiling_s:5.1f}x; {ceiling_s / walk_s:.0%} of the ceiling; "
                f"walked {walks[-1].distance_m * 100:.1f} cm; {robot.model.nv} dofs, "
                f"{robot.model.neq} equalities, {settings.step * 1000:g} ms step"
            )
        lean, full = figures[f"{name}/lean"], figures[f"{name}/full"]
        ratio = lean["walk_x_real_time"] / full["walk_x_real_time"]
        print(f"{name:>6}: lean walk / full walk {ratio:.1f}x")
    print(json.dumps(figures))


TIMED_WALK = """
import json, sys, time
from linkevo.sim.robot.leg import leg_from_genome
from linkevo.sim.linkage.linkage_doc import from_document
from linkevo.sim.robot.hexapod import FLOORS
try:
    from linkevo.sim.robot.walking import WalkSettings, walk
except ImportError:  # a tree from before sim/walk.py was named sim/robot/walking.py
    from linkevo.sim.walk import WalkSettings, walk
linkage, floor, model, seconds = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
leg = leg_from_genome(*from_document(json.load(open(linkage))))
settings = WalkSettings(seconds=seconds, model=model)
walk(leg, FLOORS[floor], settings=settings)  # warm
start = time.perf_counter()
result = walk(leg, FLOORS[floor], settings=settings)
print(time.perf_counter() - start, result.distance_m)
"""


def against(args: argparse.Namespace) -> None:
    """Prints, per floor and model, the best walk time of this tree's code and of
    `args.against`'s, taking turns, and their ratio."""
    from trees import tree_env  # benchmarks/trees.py, beside this script

    repo = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory(prefix="linkevo-walk-speed-") as tmp:
        trees = {"this tree": tree_env(repo, Path(tmp))}
        trees[str(args.against)] = tree_env(args.against, Path(tmp))
        for name in args.floor:
            for model in MODELS:
                best: dict[str, tuple[float, float]] = {}
                for _ in range(args.repeats):
                    for tree, env in trees.items():
                        done = subprocess.run(
                            [
                                sys.executable,
                                "-c",
                                TIMED_WALK,
                                str(args.linkage.resolve()),
                                name,
                                model,
                                str(args.seconds),
                            ],
                            env=env,
                            capture_output=True,
                            text=True,
                            check=True,
                        )
                        seconds, distance = map(float, done.stdout.split())
                        if tree not in best or seconds < best[tree][0]:
                            best[tree] = (seconds, distance)
                times = ", ".join(
                    f"{tree} {s:.3f} s ({d * 100:.1f} cm)" for tree, (s, d) in best.items()
                )
                this, other = best["this tree"][0], best[str(args.against)][0]
                print(
                    f"{name:>6} {model:>4}: {times}; {args.against} / this tree {other / this:.2f}"
                )


def _timed(run) -> float:
    start = time.perf_counter()
    run()
    return time.perf_counter() - start


def _bare(robot, ticks: int) -> None:
    """Steps the robot in 20-ms control ticks with constant motor goals."""
    model, data = robot.model, mujoco.MjData(robot.model)
    data.ctrl[:] = 2.6
    steps = round(0.02 / model.opt.timestep)
    for _ in range(ticks):
        robot.loads.update(model, data)
        mujoco.mj_step(model, data, nstep=steps)


if __name__ == "__main__":
    main()
