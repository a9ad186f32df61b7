"""Times the study's full grid: wall time, where it goes, and how close it is to ideal.

Either launches the grid (`configs/paper.toml`, optionally with RANDOM and legacy mode)
into a fresh store, or (`--grid-id`) reads a grid already run into a store. From MLflow it
prints the grid's wall time (the parent run's start to its end), each approach's median
trial time, the sum of all trial times, and the ideal wall time of that work on the
cluster's slots (sum / concurrent trials), with the ratio wall / ideal: 1.0 means no time
lost between trials.

    .venv/bin/python benchmarks/study_grid.py                     # runs the study (~20 min)
    .venv/bin/python benchmarks/study_grid.py --random --mode legacy
    .venv/bin/python benchmarks/study_grid.py --grid-id GRID --tracking-uri runs/
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from linkevo.orchestrator.config import load
from linkevo.orchestrator.reservation import Cluster, Reservation
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.runs import RunStore
from linkevo.workers.store.tracking import resolve_tracking_uri

ROOT = Path(__file__).resolve().parents[1]
SEVEN = '["EA","NSGA2","MAP-WH","MAP-LIS","MAP-ST","MAP-AU","RANDOM"]'


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid-id", help="read this grid instead of running one")
    parser.add_argument("--tracking-uri", help="its store (default: runs/)")
    parser.add_argument("--mode", default="paper", help="paper or legacy (when running)")
    parser.add_argument("--random", action="store_true", help="add RANDOM (when running)")
    return parser.parse_args()


def run_grid(args: argparse.Namespace, store: Path) -> str:
    """Runs the study grid into `store` through the CLI; returns its grid id."""
    command = [
        sys.executable,
        "-m",
        "linkevo.orchestrator",
        "grid",
        str(ROOT / "configs/paper.toml"),
    ]
    command += ["--no-progress", "--tracking-uri", str(store), "--set", f"mode={args.mode}"]
    if args.random:
        command += ["--set", f"approaches={SEVEN}"]
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=True)
    return done.stdout.split()[1].rstrip(":")


def main() -> None:
    """Prints the grid's timing table and the wall / ideal ratio."""
    args = parse_args()
    with tempfile.TemporaryDirectory(prefix="linkevo-study-") as tmp:
        uri = resolve_tracking_uri(args.tracking_uri or (None if args.grid_id else tmp))
        grid_id = args.grid_id or run_grid(args, Path(tmp))
        store = RunStore(uri)
        (parent,) = store.grid_runs(grid_id)
        trials = store.trial_runs(grid_id)
        config_path = store.download(parent.info.run_id, layout.GRID_CONFIG_TOML, Path(tmp))
        config = load(config_path)
    seconds = {r: (r.info.end_time - r.info.start_time) / 1000 for r in trials if r.info.end_time}
    wall = (parent.info.end_time - parent.info.start_time) / 1000
    slots = Reservation.plan(config, len(trials), Cluster.this_machine()).concurrent
    print(f"grid {grid_id}: {len(trials)} trials, mode {config.mode}, {slots} at a time")
    print(f"{'approach':<9} {'trials':>6} {'median s':>9} {'total s':>9}")
    for approach in config.approaches:
        times = [s for r, s in seconds.items() if r.data.tags["approach"] == approach]
        print(f"{approach:<9} {len(times):>6} {statistics.median(times):>9.1f} {sum(times):>9.0f}")
    work = sum(seconds.values())
    ideal = work / slots
    print(f"sum of trial times {work:.0f} s; ideal wall on {slots} slots {ideal:.0f} s")
    print(f"grid wall time {wall:.0f} s ({wall / 60:.1f} min); wall / ideal {wall / ideal:.3f}")


if __name__ == "__main__":
    main()
