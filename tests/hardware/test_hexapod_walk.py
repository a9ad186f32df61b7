"""The Hexapod against the bus emulator: start-up order, phase lock, safety and shutdown."""

from __future__ import annotations

import csv
import itertools
import os
import re
import signal
import threading
import time

import numpy as np
import pytest

from linkevo.hardware import control_table as ct
from linkevo.hardware import protocol as p
from linkevo.hardware.errors import (
    AlignmentError,
    HardwareError,
    MotorNotResponding,
    SafetyStop,
    ShutdownIncomplete,
    StopRequested,
    WrongModel,
)
from linkevo.hardware.gait import leg_phase, phase_separation, wrap
from linkevo.hardware.hexapod import Hexapod
from linkevo.hardware.session import run_walk
from tests.helpers.hexapod import TEST_IDS

PHASE_TOLERANCE_DEG = 5.0
"""Tripods must stay within this of half a turn apart (and each leg of its own tripod)."""
CLOCK_TOLERANCE_DEG = 10.0
"""The median settled tick must have every leg within this of its clock target."""


def assert_all_stopped(emu):
    for motor_id, state in emu.snapshots().items():
        assert state.goal_velocity == 0, f"motor {motor_id} still has a goal velocity"
        assert not state.torque_enabled, f"motor {motor_id} still has torque on"


def read_telemetry(path):
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    time_s = np.array([float(r["time_s"]) for r in rows])
    positions = np.array([[int(r[f"m{i}_position"]) for i in TEST_IDS] for r in rows])
    velocities = np.array([[float(r[f"m{i}_velocity_rpm"]) for i in TEST_IDS] for r in rows])
    return time_s, positions, velocities


def is_watchdog_write(packet):
    """Returns whether a logged packet is a SYNC_WRITE of Bus Watchdog (a re-arm)."""
    address = int.from_bytes(packet.params[:2], "little")
    return packet.instruction == p.SYNC_WRITE and address == ct.BUS_WATCHDOG.address


def test_start_up_align_and_walk_write_in_the_documented_order(emulator, config_for):
    emu = emulator()
    config = config_for(emu.port)
    with Hexapod(config) as robot:
        robot.start_up()
        robot.align()
        walk_from = len(emu.packets())
        result = robot.walk(0.3)
    profile = round(ct.rpm_to_units(config.align.profile_velocity_rpm))
    watchdog = config.safety.bus_watchdog_ms // 20
    expected = [
        (64, 0),
        (98, 0),
        (9, 0),  # start-up: torque off, watchdog off, return delay 0
        (11, 3),
        (112, profile),
        (64, 1),
        (64, 0),  # align in position mode
        (11, 1),
        (104, 0),
        (64, 1),
        (98, watchdog),  # velocity mode, then walk
        (64, 0),  # shutdown
    ]
    for motor_id in TEST_IDS:
        writes = [
            (w.address, w.value)
            for w in emu.writes()
            if w.motor_id == motor_id and w.instruction == p.WRITE
        ]
        # A write retried after a slow reply shows up twice in a row; count it once.
        writes = [w for i, w in enumerate(writes) if i == 0 or writes[i - 1] != w]
        assert writes == expected, f"motor {motor_id}"
    assert emu.snapshot(1).return_delay_time == 0
    # Per tick: one SYNC_READ, then one SYNC_WRITE (none after a missed read). A stall of
    # the host adds a watchdog re-arm (two SYNC_WRITEs) before a tick's goal write.
    walking = emu.packets()[walk_from:]
    assert sum(map(is_watchdog_write, walking)) == 2 * result.watchdog_rearms
    walking = [q.instruction for q in walking if not is_watchdog_write(q)]
    first_read = walking.index(p.SYNC_READ)
    loop = walking[first_read : walking.index(p.WRITE, first_read) - 1]
    assert set(loop) == {p.SYNC_READ, p.SYNC_WRITE}
    assert loop.count(p.SYNC_WRITE) == result.ticks >= 1
    assert loop.count(p.SYNC_READ) == result.ticks + result.missed_reads
    assert all(a == p.SYNC_READ for a, b in itertools.pairwise(loop) if b == p.SYNC_WRITE)
    assert result.ticks + result.skipped_ticks + result.missed_reads == 15
    assert_all_stopped(emu)


def test_a_stall_longer_than_the_walk_skips_only_the_slots_left(emulator, config_for):
    emu = emulator()
    ticks = []  # after the fifth tick the clock jumps 60 s ahead, as if the process slept

    def clock():
        return time.monotonic() + (60.0 if len(ticks) >= 5 else 0.0)

    with Hexapod(config_for(emu.port), clock=clock) as robot:
        robot.start_up()
        result = robot.walk(0.5, on_tick=ticks.append)
    assert result.ticks == len(ticks) == 5
    assert result.ticks + result.skipped_ticks + result.missed_reads == 25
    assert result.duration_s > 60.0
    assert_all_stopped(emu)


def test_a_host_stall_past_the_bus_watchdog_rearms_it_and_the_legs_walk_on(emulator, config_for):
    emu = emulator()
    config = config_for(emu.port)
    watchdog_s = config.safety.bus_watchdog_ms / 1000.0
    records = []

    def on_tick(record):
        records.append(record)
        if len(records) == 10:
            time.sleep(watchdog_s + 0.3)  # the host stalls: every motor's watchdog trips

    with Hexapod(config) as robot:
        robot.start_up()
        started = len(emu.packets())
        result = robot.walk(2.0, on_tick=on_tick)
    directions = np.array([m.direction for m in config.motors])

    def present_velocities(record):
        return np.array([record.statuses[i].values["present_velocity"] for i in TEST_IDS])

    assert np.all(present_velocities(records[10]) == 0)  # the trip stopped every leg
    assert np.all(np.sign(present_velocities(records[-1])) == directions)  # walking again
    assert result.watchdog_rearms >= 1
    since = emu.packets()[started].time
    writes = [w for w in emu.writes() if w.time >= since]
    values = [w.value for w in writes if w.address == ct.BUS_WATCHDOG.address]
    rearm = [0] * len(TEST_IDS) + [config.safety.bus_watchdog_ms // 20] * len(TEST_IDS)
    assert values[len(TEST_IDS) :] == rearm * result.watchdog_rearms  # after walk's own
    assert_all_stopped(emu)


def test_ten_second_walk_keeps_tripods_half_a_turn_apart(emulator, config_for, tmp_path):
    emu = emulator()
    config = config_for(emu.port)
    telemetry = tmp_path / "walk.csv"
    result = run_walk(config, 10.0, telemetry=telemetry)
    time_s, positions, velocities = read_telemetry(telemetry)
    assert len(time_s) == result.ticks
    assert result.ticks + result.skipped_ticks + result.missed_reads == 500
    zeros = np.array([m.zero for m in config.motors])
    directions = np.array([m.direction for m in config.motors])
    tripod_a = np.array([m.phase_deg == 0.0 for m in config.motors])
    settled = time_s >= 1.0
    assert settled.sum() >= 50  # the checks below are not vacuous, however loaded the machine
    tolerance = np.radians(PHASE_TOLERANCE_DEG)
    for row in positions[settled]:
        phases = leg_phase(row, zeros, directions)
        assert abs(phase_separation(phases, tripod_a) - np.pi) <= tolerance
        for tripod in (tripod_a, ~tripod_a):
            spread = np.angle(np.exp(1j * (phases[tripod] - phases[tripod][0])))
            assert np.all(np.abs(spread) <= tolerance)
    # Direction signs: every leg turns forward by speed * time, reversed motors backwards.
    turns = (positions[-1] - positions[0]) * directions / ct.POSITION_UNITS_PER_TURN
    expected_turns = config.gait.speed_rpm / 60.0 * (time_s[-1] - time_s[0])
    assert np.allclose(turns, expected_turns, rtol=0.05)
    # A tick after a host stall longer than the Bus Watchdog may read stopped legs (the
    # watchdog is re-armed before its goal write); every other one turns its leg's way.
    watchdog_s = config.safety.bus_watchdog_ms / 1000.0
    after_stall = np.diff(time_s, prepend=time_s[0]) > watchdog_s / 2
    assert np.all(np.sign(velocities[settled & ~after_stall]) == directions)
    # Against the clock itself: a stall between a tick's time stamp and the emulator's
    # sampling shows as phase error in that tick (and in the catch-up after it), so the
    # bound holds the median settled tick, not the worst one (tests assert no timings).
    offsets = np.radians([m.phase_deg for m in config.motors])
    targets = 2 * np.pi * config.gait.speed_rpm / 60.0 * time_s[settled, None] + offsets
    measured = np.array([leg_phase(row, zeros, directions) for row in positions[settled]])
    worst_leg = np.abs(wrap(targets - measured)).max(axis=1)
    assert np.median(worst_leg) <= np.radians(CLOCK_TOLERANCE_DEG)
    assert_all_stopped(emu)


def test_exception_mid_walk_leaves_every_motor_stopped(emulator, config_for):
    emu = emulator()
    seen = []

    def explode(record):
        seen.append(record)
        if len(seen) == 10:
            raise RuntimeError("operator code failed")

    robot = Hexapod(config_for(emu.port))
    with pytest.raises(RuntimeError, match="operator code failed"), robot:
        robot.start_up()
        robot.align()
        robot.walk(5.0, on_tick=explode)
    assert any(r.goal_velocities[1] != 0 for r in seen)
    assert not robot.bus.is_open
    assert_all_stopped(emu)


def test_sigterm_mid_walk_stops_motors_and_keeps_telemetry(emulator, config_for, tmp_path):
    emu = emulator()
    previous = signal.getsignal(signal.SIGTERM)
    ticks = []

    def on_tick(record):
        ticks.append(record)
        if len(ticks) == 20:
            threading.Thread(target=os.kill, args=(os.getpid(), signal.SIGTERM)).start()

    with pytest.raises(StopRequested, match="stopped by SIGTERM"):
        run_walk(config_for(emu.port), 30.0, telemetry=tmp_path / "t.csv", on_tick=on_tick)
    assert signal.getsignal(signal.SIGTERM) is previous
    assert 20 <= len(ticks) < 200
    time_s, _, _ = read_telemetry(tmp_path / "t.csv")
    assert len(time_s) == len(ticks)
    assert_all_stopped(emu)


def test_overheating_stops_the_walk_with_a_clear_message(emulator, config_for):
    emu = emulator()

    def heat_up(record):
        if record.time_s > 0.2 and emu.snapshot(4).temperature == 30:
            emu.heat(4, 60.0)

    with pytest.raises(
        SafetyStop,
        match=r"^motor 4 \(right-front\): temperature \d+ °C reached the limit 70 °C; walk stopped",
    ) as info:
        run_walk(config_for(emu.port), 10.0, on_tick=heat_up)
    assert info.value.motor_id == 4
    # 1.2 °C per 20 ms tick: a stalled tick may see more than 79 °C, never less than 70.
    assert int(re.search(r"temperature (\d+) °C", str(info.value))[1]) >= 70
    assert_all_stopped(emu)


def test_missing_motor_at_start_up_is_named(emulator, config_for):
    emu = emulator([1, 2, 3, 4, 6])
    with pytest.raises(MotorNotResponding, match=r"^motor 5 did not answer \(ping\)"):
        run_walk(config_for(emu.port), 1.0)
    assert_all_stopped(emu)


def test_motor_that_stops_answering_mid_walk_is_named_and_its_torque_reported(emulator, config_for):
    """The walk ends naming the motor; its torque could not be turned off, which the
    error says instead of claiming every motor stopped."""
    emu = emulator()

    def unplug(record):
        if len(emu.packets()) and record.time_s > 0.2:
            emu.drop_replies(3, 100_000)

    with pytest.raises(ShutdownIncomplete, match=r"torque off failed: motor 3") as info:
        run_walk(config_for(emu.port), 10.0, on_tick=unplug)
    cause = info.value.__cause__
    assert isinstance(cause, MotorNotResponding)
    assert re.search(r"motor 3 did not answer \(sync read\)", str(cause))
    others = {i: s for i, s in emu.snapshots().items() if i != 3}
    assert all(not s.torque_enabled and s.goal_velocity == 0 for s in others.values())


def test_overload_is_rebooted_when_policy_allows(emulator, config_for):
    emu = emulator()
    config = config_for(emu.port, safety={"on_hardware_error": "reboot"})
    injected = []

    def overload(record):
        if record.time_s > 0.3 and not injected:
            injected.append(record.time_s)
            emu.set_hardware_error(2, 1 << ct.OVERLOAD_BIT)

    result = run_walk(config, 1.5, on_tick=overload)
    assert result.reboots == 1
    assert {q.motor_id for q in emu.packets() if q.instruction == p.REBOOT} == {2}
    assert emu.snapshot(2).hardware_error == 0
    assert_all_stopped(emu)


def test_overload_stops_the_walk_under_the_default_policy(emulator, config_for):
    emu = emulator()

    def overload(record):
        if record.time_s > 0.3:
            emu.set_hardware_error(2, 1 << ct.OVERLOAD_BIT)

    with pytest.raises(SafetyStop, match=r"motor 2 \(left-middle\): hardware error: overload"):
        run_walk(config_for(emu.port), 5.0, on_tick=overload)
    assert_all_stopped(emu)


def test_wrong_model_is_refused_before_anything_moves(emulator, config_for):
    emu = emulator(model_number=311)
    with pytest.raises(WrongModel, match=r"motor 1 \(left-front\) reports model 311; expected"):
        run_walk(config_for(emu.port), 1.0)
    # Only the shutdown's Goal Velocity 0 and torque off were written.
    assert {(w.address, w.value) for w in emu.writes()} == {(104, 0), (64, 0)}
    assert_all_stopped(emu)


def test_gait_faster_than_the_velocity_limit_is_refused(emulator, config_for):
    emu = emulator(velocity_limit=100)
    with pytest.raises(HardwareError, match=r"motor 1 \(left-front\): gait speed 30 rpm .* is 100"):
        run_walk(config_for(emu.port), 1.0)
    assert_all_stopped(emu)


def test_alignment_timeout_names_the_late_legs(emulator, config_for):
    emu = emulator()
    config = config_for(emu.port, align={"profile_velocity_rpm": 1.0, "timeout_s": 0.2})
    with pytest.raises(AlignmentError, match=r"motor 2 \(left-middle\).*did not reach"):
        run_walk(config, 1.0)
    assert_all_stopped(emu)


def test_a_stop_requested_during_start_up_turns_no_torque_on(emulator, config_for):
    emu = emulator()
    previous = signal.getsignal(signal.SIGINT)

    def interrupt_at_first_packet():
        deadline = time.monotonic() + 10.0
        while not emu.packets() and time.monotonic() < deadline:
            time.sleep(0.0005)
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=interrupt_at_first_packet).start()
    with pytest.raises(StopRequested, match="SIGINT"):
        run_walk(config_for(emu.port), 5.0)
    assert signal.getsignal(signal.SIGINT) is previous
    torque_on = [
        w for w in emu.writes() if w.address == ct.TORQUE_ENABLE.address and w.data == b"\x01"
    ]
    modes = [w for w in emu.writes() if w.address == ct.OPERATING_MODE.address]
    assert torque_on == [] and modes == []
    assert_all_stopped(emu)


def test_a_corrupt_status_packet_costs_one_tick_not_the_walk(emulator, config_for):
    emu = emulator()
    injected = []

    def corrupt(record):
        if record.time_s > 0.3 and not injected:
            injected.append(record.time_s)
            emu.corrupt_replies(3, 1)

    result = run_walk(config_for(emu.port), 1.5, on_tick=corrupt)
    assert injected and result.missed_reads >= 1
    assert not result.stopped_early and result.ticks > 50
    assert_all_stopped(emu)
