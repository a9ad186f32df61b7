"""linkevo's shipped configs, installed with it: the grids' examples (`quick.toml`,
`paper.toml`) and the robot's default (`hexapod.toml`)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def shipped(name: str) -> Path:
    """Returns the path of a shipped config file, e.g. `shipped("hexapod.toml")`."""
    return Path(str(resources.files(__name__).joinpath(name)))
