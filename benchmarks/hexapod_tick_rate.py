"""Benchmark: the hexapod control loop's tick rate against the bus emulator.

Measures, with the real dynamixel-sdk talking to `hardware.emulator.BusEmulator` on a pty:

1. a clocked walk (`run_walk`, `--emulate` path) of `--seconds` at the config's rate:
   ticks, achieved rate, skipped slots and missed reads;
2. the loop's ceiling: back-to-back ticks (one sync read of the 21-byte state block and
   one sync write of Goal Velocity for all six motors), per second;
3. the plain reference, the authors' pattern: per motor, read Operating Mode, write Goal
   Velocity, read Present Position, as single round trips (18 per iteration), per second.

The ratio of (2) to (3) is the speed-up of one sync read + one sync write over the
single transactions. The emulator answers without USB latency, so on a real FTDI adapter
both numbers drop; the ratio only grows (each round trip pays the latency once).

    .venv/bin/python benchmarks/hexapod_tick_rate.py [--seconds 3] [--iterations 300]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from linkevo.hardware import control_table as ct
from linkevo.hardware.config import load_config
from linkevo.hardware.emulator import BusEmulator
from linkevo.hardware.hexapod import Hexapod
from linkevo.hardware.session import run_walk

REPO = Path(__file__).resolve().parent.parent


def clocked_walk(config_path: Path, seconds: float) -> None:
    """Prints the achieved rate of one simulated walk on the fixed clock."""
    config = load_config(config_path)
    result = run_walk(config, seconds, simulate=True)
    print(
        f"clocked walk {seconds:g} s at {config.gait.rate_hz:g} Hz: {result.ticks} ticks, "
        f"{result.rate_hz:.2f} Hz achieved, skipped {result.skipped_ticks}, "
        f"missed reads {result.missed_reads}"
    )


def loop_ceiling(robot: Hexapod, iterations: int) -> list[float]:
    """Returns the durations (s) of back-to-back ticks: one sync read + one sync write."""
    ids = robot.config.motor_ids
    durations = []
    for _ in range(iterations):
        start = time.perf_counter()
        robot.read_state()
        robot.bus.sync_write(ct.GOAL_VELOCITY, dict.fromkeys(ids, 0))
        durations.append(time.perf_counter() - start)
    return durations


def reference_loop(robot: Hexapod, iterations: int) -> list[float]:
    """Returns the durations (s) of the authors' iteration: 18 single round trips."""
    bus = robot.bus
    durations = []
    for _ in range(iterations):
        start = time.perf_counter()
        for motor_id in robot.config.motor_ids:
            bus.read(motor_id, ct.OPERATING_MODE)
            bus.write(motor_id, ct.GOAL_VELOCITY, 0)
            bus.read(motor_id, ct.PRESENT_POSITION)
        durations.append(time.perf_counter() - start)
    return durations


def describe(name: str, durations: list[float]) -> float:
    """Prints per-iteration statistics and returns iterations per second."""
    rate = len(durations) / sum(durations)
    p50 = statistics.median(durations) * 1e3
    p99 = sorted(durations)[int(0.99 * (len(durations) - 1))] * 1e3
    print(f"{name}: {rate:8.1f} /s   median {p50:6.2f} ms   p99 {p99:6.2f} ms")
    return rate


def main() -> None:
    """Runs the three measurements and prints the ratio."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=REPO / "configs" / "hexapod.toml")
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--iterations", type=int, default=300)
    args = parser.parse_args()

    clocked_walk(args.config, args.seconds)
    config = load_config(args.config)
    with (
        BusEmulator(config.motor_ids) as emulator,
        Hexapod(config.with_port(emulator.port)) as robot,
    ):
        robot.start_up()
        for motor_id in config.motor_ids:
            robot.bus.write(motor_id, ct.OPERATING_MODE, ct.VELOCITY_MODE)
            robot.bus.write(motor_id, ct.TORQUE_ENABLE, 1)
        ours = describe(
            "sync tick (1 sync read + 1 sync write)", loop_ceiling(robot, args.iterations)
        )
        reference = describe(
            "reference (authors' 18 single round trips)",
            reference_loop(robot, max(1, args.iterations // 3)),
        )
    print(f"ratio (ours / reference iterations per second): {ours / reference:.1f}x")


if __name__ == "__main__":
    main()
