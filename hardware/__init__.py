"""linkevo's hardware layer: the MX-28 hexapod's driver, gait, safety, emulator, field trials."""

from hardware.bus import DxlBus
from hardware.config import RobotConfig, load_config
from hardware.emulator import BusEmulator
from hardware.hexapod import Hexapod, WalkResult
from hardware.session import run_walk

__all__ = [
    "BusEmulator",
    "DxlBus",
    "Hexapod",
    "RobotConfig",
    "WalkResult",
    "load_config",
    "run_walk",
]
