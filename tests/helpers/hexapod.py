"""Test data for the hardware tests: the six test motors and TOML-shaped configs."""

from __future__ import annotations

# Left-front, left-middle, left-rear, right-front, right-middle, right-rear. Tripod A
# (phase 0) = ids 1, 3, 5; tripod B (phase 180) = ids 2, 4, 6. Right-side motors are
# mirror-mounted (direction -1). Zeros differ so that calibration is exercised.
TEST_MOTORS = (
    {"id": 1, "name": "left-front", "direction": 1, "phase_deg": 0.0, "zero": 100},
    {"id": 2, "name": "left-middle", "direction": 1, "phase_deg": 180.0, "zero": 3000},
    {"id": 3, "name": "left-rear", "direction": 1, "phase_deg": 0.0, "zero": 0},
    {"id": 4, "name": "right-front", "direction": -1, "phase_deg": 180.0, "zero": 500},
    {"id": 5, "name": "right-middle", "direction": -1, "phase_deg": 0.0, "zero": 4000},
    {"id": 6, "name": "right-rear", "direction": -1, "phase_deg": 180.0, "zero": 2048},
)
TEST_IDS = [m["id"] for m in TEST_MOTORS]


EMULATOR_LATENCY_MS = 50.0
"""Reply allowance for the bus emulator, a Python thread of the test process: its replies
wait on thread scheduling, not on a USB latency timer, and on a loaded 2-core machine the
FTDI default's 2 x 16 + 2 ms has run out before one came (docs/hardware.md)."""


def raw_config(port: str, **sections: dict) -> dict:
    """Returns a TOML-shaped test config; `sections` override whole tables' keys."""
    raw = {
        "bus": {"port": port, "baudrate": 1_000_000, "latency_ms": EMULATOR_LATENCY_MS},
        "gait": {"rate_hz": 50.0, "speed_rpm": 30.0},
        "align": {"profile_velocity_rpm": 50.0, "tolerance_deg": 2.0, "timeout_s": 10.0},
        "safety": {"bus_watchdog_ms": 500},
        "motors": [dict(m) for m in TEST_MOTORS],
    }
    for name, values in sections.items():
        raw[name] = {**raw.get(name, {}), **values}
    return raw


def toml_text(raw: dict) -> str:
    """Returns `raw` written as TOML (enough for the flat tables used here)."""

    def value(v: object) -> str:
        if isinstance(v, str):
            return f'"{v}"'
        return repr(v).lower() if isinstance(v, bool) else repr(v)

    lines = []
    for name, table in raw.items():
        if name == "motors":
            continue
        lines.append(f"[{name}]")
        lines += [f"{k} = {value(v)}" for k, v in table.items()]
    for motor in raw["motors"]:
        lines.append("[[motors]]")
        lines += [f"{k} = {value(v)}" for k, v in motor.items()]
    return "\n".join(lines) + "\n"
