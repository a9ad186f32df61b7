"""Provides run_walk: one guarded walk (start-up, alignment, walk, safe shutdown) from a config."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from linkevo.hardware.config import RobotConfig
from linkevo.hardware.emulator import BusEmulator
from linkevo.hardware.errors import ShutdownIncomplete, StopRequested
from linkevo.hardware.hexapod import Hexapod, WalkResult
from linkevo.hardware.safety import SignalGuard
from linkevo.hardware.telemetry import TelemetryWriter, TickRecord

if TYPE_CHECKING:
    from linkevo.hardware.physics_bus import PhysicsWorld


def run_walk(
    config: RobotConfig,
    seconds: float,
    *,
    telemetry: str | Path | None = None,
    simulate: bool = False,
    physics: PhysicsWorld | None = None,
    on_tick: Callable[[TickRecord], None] | None = None,
) -> WalkResult:
    """Walks the robot once and always leaves it stopped with torque off.

    Args:
        config: the robot config.
        seconds: walking time (after start-up and alignment).
        telemetry: CSV path for one row per tick; written atomically, kept on a stop.
        simulate: run against an in-process bus emulator on a pty instead of the port.
        physics: with `simulate`, the emulator's motors are this simulated robot's cranks
            (`hardware.physics_bus`); None: they turn as commanded.
        on_tick: called with every tick's record (after the telemetry row).

    Raises:
        StopRequested: SIGINT or SIGTERM arrived; the motors were stopped first.
        ShutdownIncomplete: the shutdown failed on some motor (raised from whatever error
            ended the walk); every other error comes after a complete shutdown.
    """
    robots: list[Hexapod] = []
    try:
        result = _walk_once(config, seconds, telemetry, simulate, physics, on_tick, robots)
    except BaseException as exc:
        _check_shutdown(robots, exc)
        raise
    _check_shutdown(robots, None)
    return result


def _check_shutdown(robots: list[Hexapod], cause: BaseException | None) -> None:
    """Raises ShutdownIncomplete (from `cause`) when the robot's shutdown left problems."""
    problems = [p for robot in robots for p in robot.shutdown_problems]
    if problems:
        raise ShutdownIncomplete(
            "shutdown incomplete, motors may still hold torque: " + "; ".join(problems)
        ) from cause


def _walk_once(
    config: RobotConfig,
    seconds: float,
    telemetry: str | Path | None,
    simulate: bool,
    physics: PhysicsWorld | None,
    on_tick: Callable[[TickRecord], None] | None,
    robots: list[Hexapod],
) -> WalkResult:
    with contextlib.ExitStack() as stack:
        if simulate:
            factory = {} if physics is None else {"motor_factory": physics.motor_factory}
            emulator = stack.enter_context(BusEmulator(config.motor_ids, **factory))
            config = config.with_port(emulator.port)
        guard = stack.enter_context(SignalGuard())
        sinks = [] if on_tick is None else [on_tick]
        if telemetry is not None:
            sinks.insert(0, stack.enter_context(TelemetryWriter(telemetry, config.motor_ids)))
        robot = stack.enter_context(Hexapod(config))
        robots.append(robot)
        robot.start_up()
        robot.align(stop=guard.event)

        def fan_out(record: TickRecord) -> None:
            for sink in sinks:
                sink(record)

        result = robot.walk(seconds, on_tick=fan_out, stop=guard.event)
    if guard.signal_name is not None:
        raise StopRequested(guard.signal_name)
    return result
