"""Provides a grid config as text: `--set key=value` overrides read and applied to a
TOML table, the resolved config written back as TOML (`to_toml`, which `config.load` reads
to an equal config) and flattened into MLflow params (`flatten`)."""

from __future__ import annotations

import tomllib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from linkevo.orchestrator.config import GridConfig


def parse_override(text: str) -> tuple[list[str], Any]:
    """Returns the dotted key path and TOML value of one `--set key=value` override.

    The value is read as a TOML value (`3`, `"EA"`, `["EA","MAP-LIS"]`, `true`); a bare
    word that is not valid TOML (`legacy`) is taken as a string.
    """
    from linkevo.orchestrator.config import ConfigError

    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ConfigError(f"--set {text!r}: expected KEY=VALUE, e.g. --set trials=3")
    raw = raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError as exc:
        if not raw or any(c in raw for c in "[]{}\"'=,"):
            raise ConfigError(f"--set {text!r}: the value is not a TOML value ({exc})") from exc
        value = raw
    return key.split("."), value


def apply_overrides(data: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """Returns a copy of the TOML table with every `--set key=value` applied in order."""
    from linkevo.orchestrator.config import KEYS, ConfigError

    out = dict(data)
    if isinstance(out.get("options"), dict):
        out["options"] = {
            k: dict(v) if isinstance(v, dict) else v for k, v in out["options"].items()
        }
    for text in overrides:
        path, value = parse_override(text)
        if len(path) == 1:
            out[path[0]] = value
        elif len(path) == 3 and path[0] == "options":
            tables = out.setdefault("options", {})
            tables[path[1]] = {**tables.get(path[1], {}), path[2]: value}
        else:
            raise ConfigError(
                f"--set {text!r}: only 'options.<approach>.<name>' may be dotted; "
                "allowed keys: " + ", ".join(KEYS)
            )
    return out


def flatten(data: dict[str, Any], prefix: str = "") -> dict[str, str]:
    """Returns `{"key": str(value)}` with nested tables as dotted keys (MLflow params)."""
    out: dict[str, str] = {}
    for key, value in data.items():
        if isinstance(value, dict):
            out.update(flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = str(value)
    return out


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        escaped = value.replace("\\", "\\\\").replace('"', '\\"')
        return f'"{escaped}"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {value!r} as a TOML value")


def to_toml(cfg: GridConfig) -> str:
    """Returns the resolved config as TOML text that `load` reads back to an equal config."""
    data = cfg.to_dict()
    options = data.pop("options")
    lines = [f"{key} = {_toml_value(value)}" for key, value in data.items()]
    for approach, table in options.items():
        lines += ["", f'[options."{approach}"]']
        lines += [f"{key} = {_toml_value(value)}" for key, value in table.items()]
    return "\n".join(lines) + "\n"
