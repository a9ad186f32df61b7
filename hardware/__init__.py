"""linkevo's hardware layer: the MX-28 hexapod's driver, gait, safety, emulator, field trials."""

from linkevo.hardware.bus import DxlBus
from linkevo.hardware.config import RobotConfig, load_config
from linkevo.hardware.emulator import BusEmulator
from linkevo.hardware.hexapod import Hexapod, WalkResult
from linkevo.hardware.session import run_walk

__all__ = [
    "BusEmulator",
    "DxlBus",
    "Hexapod",
    "RobotConfig",
    "WalkResult",
    "load_config",
    "run_walk",
]
