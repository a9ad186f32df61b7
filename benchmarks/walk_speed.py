"""Benchmark: how fast the 3-D walk runs on one core, against MuJoCo's own ceiling.

Run: `.venv/bin/python benchmarks/walk_speed.py` (options: --linkage FILE.json, --seconds,
--repeats, --floor). The robot is the study's hexapod on six copies of a linkage: by
default `benchmarks/walk_linkage.json`, the first robot of MAP-LIS in the paper-mode study
grid (`linkevo hexapod study`). The process is pinned to one core.

Two figures per floor, each the best of `--repeats` runs, simulated seconds per wall
second:
- **walk**: `sim.walk.walk` as `linkevo hexapod simulate` runs it: model built, settled,
  then the gait's controller, the motors' velocity loop and the records a builder reads;
- **ceiling**: a bare `mujoco.mj_step` loop over the same model for the same number of
  steps with constant motor voltages, nothing recorded (what MuJoCo itself allows).
Their ratio is the share of the ceiling the walk reaches. Goal: walk >= 20x real time (a
10-s trial in <= 0.5 s).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import mujoco
import numpy as np

from linkevo.sim.leg import leg_from_genome
from linkevo.sim.linkage_doc import from_document
from linkevo.sim.robot import FLOORS, LEG_SLOTS, TRIPOD_OFFSETS_DEG
from linkevo.sim.walk import WalkSettings, walk
from linkevo.sim.walk_model import build_robot

DEFAULT_LINKAGE = Path(__file__).with_name("walk_linkage.json")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--linkage", type=Path, default=DEFAULT_LINKAGE)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--floor", nargs="+", default=list(FLOORS))
    args = parser.parse_args()
    os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    genome, mode = from_document(json.loads(args.linkage.read_text(encoding="utf-8")))
    leg = leg_from_genome(genome, mode)
    settings = WalkSettings(seconds=args.seconds)
    simulated = settings.seconds + settings.settle_s
    print(
        f"{platform.processor() or platform.machine()}, mujoco {mujoco.__version__}, one core; "
        f"leg {args.linkage.name}: {leg.n_parts} moving parts, {len(leg.beams)} beams"
    )
    figures = {}
    for name in args.floor:
        floor = FLOORS[name]
        walk_s = min(
            _timed(lambda f=floor: walk(leg, f, settings=settings)) for _ in range(args.repeats)
        )
        robot = build_robot(
            dict.fromkeys(LEG_SLOTS, leg),
            {s: np.radians(TRIPOD_OFFSETS_DEG[s]) for s in LEG_SLOTS},
            floor,
        )
        steps = round(simulated / robot.model.opt.timestep)
        ceiling_s = min(_timed(lambda r=robot, n=steps: _bare(r, n)) for _ in range(args.repeats))
        figures[name] = {
            "walk_x_real_time": round(simulated / walk_s, 1),
            "ceiling_x_real_time": round(simulated / ceiling_s, 1),
            "walk_s_per_10s_trial": round(walk_s * 10.0 / args.seconds, 3),
            "share_of_ceiling": round(ceiling_s / walk_s, 3),
            "bodies": int(robot.model.nbody),
            "loop_closures": int(robot.model.neq),
        }
        print(
            f"{name:>6}: walk {simulated / walk_s:5.1f}x real time ({walk_s:.3f} s for "
            f"{simulated:g} simulated s); ceiling {simulated / ceiling_s:5.1f}x; the walk "
            f"reaches {ceiling_s / walk_s:.0%} of the ceiling"
        )
    print(json.dumps(figures))


def _timed(run) -> float:
    start = time.perf_counter()
    run()
    return time.perf_counter() - start


def _bare(robot, steps: int) -> None:
    data = mujoco.MjData(robot.model)
    data.ctrl[:] = 4.0
    mujoco.mj_step(robot.model, data, nstep=steps)


if __name__ == "__main__":
    main()
