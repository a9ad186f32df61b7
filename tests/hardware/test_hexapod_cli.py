"""`linkevo hexapod walk`: tick rate, Ctrl-C in a real subprocess, bad input."""

from __future__ import annotations

import csv
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from linkevo.hardware import control_table as ct
from linkevo.hardware.config import GaitConfig
from linkevo.orchestrator.cli import main
from tests.helpers.hexapod import TEST_IDS

LINKEVO = Path(sys.executable).parent / "linkevo"


def test_simulated_three_second_walk_accounts_for_every_50_hz_slot(config_file, tmp_path, capsys):
    """Every slot of the 50 Hz clock is a tick, a missed read or a skipped slot, and every
    tick has its telemetry row. How many are ticks depends on the machine's load (a stall
    beyond [gait] max_lag_s skips slots), so that count is printed, never asserted."""
    telemetry = tmp_path / "out" / "walk.csv"
    cfg = config_file("/dev/unused")
    code = main(
        [
            "hexapod",
            "walk",
            "--config",
            str(cfg),
            "--seconds",
            "3",
            "--emulate",
            "--telemetry",
            str(telemetry),
        ]
    )
    assert code == 0
    with open(telemetry, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    assert header[:5] == [
        "time_s",
        "m1_position",
        "m1_velocity_rpm",
        "m1_load_percent",
        "m1_temperature_c",
    ]
    assert len(header) == 1 + 4 * len(TEST_IDS)
    out = capsys.readouterr().out
    counts = re.search(r"(\d+) ticks at .* skipped (\d+), missed reads (\d+),", out)
    ticks, skipped, missed = map(int, counts.groups())
    assert ticks + skipped + missed == 150
    assert len(body) == ticks > 0
    times = [float(r[0]) for r in body]
    assert times == sorted(times) and times[-1] < 3.0 + GaitConfig().max_lag_s
    assert not list(telemetry.parent.glob(".walk.csv.*"))


def test_simulate_physics_walks_a_linkage_document_and_refuses_bad_input(config_file, capsys):
    cfg = config_file("/dev/unused")
    linkage = Path(__file__).parents[2] / "benchmarks" / "walk_linkage.json"
    base = ["hexapod", "walk", "--config", str(cfg), "--seconds", "1", "--emulate", "physics"]
    assert main([*base, "--linkage", str(linkage), "--floor", "carpet"]) == 0
    moved = re.search(r"the simulated robot moved (-?[\d.]+) cm along", capsys.readouterr().out)
    assert moved and float(moved.group(1)) > 2.0
    for extra, message in (
        ([], "--emulate physics needs --linkage"),
        (["--linkage", str(linkage), "--floor", "ice"], "invalid choice: 'ice' (choose from"),
    ):
        assert main([*base, *extra]) == 2
        assert message in capsys.readouterr().err
    assert (
        main(["hexapod", "walk", "--config", str(cfg), "--seconds", "1", "--emulate", "gazebo"])
        == 2
    )
    assert "--emulate: invalid choice: 'gazebo' (choose from 'bus', 'physics')" in (
        capsys.readouterr().err
    )


def test_sigint_to_a_walking_process_leaves_motors_stopped(emulator, config_file):
    emu = emulator()
    cfg = config_file(emu.port)
    proc = subprocess.Popen(
        [str(LINKEVO), "hexapod", "walk", "--config", str(cfg), "--seconds", "120"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline and proc.poll() is None:
            states = emu.snapshots().values()
            if all(s.operating_mode == ct.VELOCITY_MODE and s.goal_velocity for s in states):
                break
            time.sleep(0.05)
        time.sleep(0.5)
        assert proc.poll() is None, proc.communicate()
        moving = emu.snapshots()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert all(s.torque_enabled and s.goal_velocity for s in moving.values())
    assert proc.returncode == 130
    assert "stopped by SIGINT; motors stopped, torque off" in err
    for motor_id, state in emu.snapshots().items():
        assert state.goal_velocity == 0, motor_id
        assert not state.torque_enabled, motor_id
        line = next(x for x in err.splitlines() if x.startswith(f"stop: motor {motor_id} "))
        assert line.endswith(": Goal Velocity 0, torque off (read back)"), err


def test_bad_config_is_a_usage_error_naming_the_value(tmp_path, capsys):
    cfg = tmp_path / "robot.toml"
    cfg.write_text('[bus]\nport = "x"\n[[motors]]\nid = 300\n', encoding="utf-8")
    assert main(["hexapod", "walk", "--config", str(cfg), "--seconds", "1"]) == 2
    assert "id = 300 is out of range [0, 252]" in capsys.readouterr().err


@pytest.mark.parametrize("seconds", ["0", "-1", "nan"])
def test_non_positive_seconds_is_refused(seconds, config_file, capsys):
    code = main(["hexapod", "walk", "--config", str(config_file("x")), "--seconds", seconds])
    assert code == 2
    said = capsys.readouterr().err
    assert f"--seconds: '{seconds}' is not allowed: a number of seconds in (0, 600]" in said


def test_unreachable_port_is_reported(config_file, capsys):
    code = main(
        ["hexapod", "walk", "--config", str(config_file("/dev/no-such-port")), "--seconds", "1"]
    )
    assert code == 1
    assert "cannot open port '/dev/no-such-port'" in capsys.readouterr().err


def test_a_walk_that_never_ticked_leaves_an_existing_telemetry_file(config_file, tmp_path):
    telemetry = tmp_path / "t.csv"
    telemetry.write_text("an earlier walk's rows\n")
    cfg = config_file("/dev/no-such-port")
    argv = ["hexapod", "walk", "--config", str(cfg), "--seconds", "1"]
    assert main([*argv, "--telemetry", str(telemetry)]) == 1
    assert telemetry.read_text() == "an earlier walk's rows\n"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
