"""Provides GridConfig: the validated, resolved configuration of one grid of trials, read
from TOML with `--set` overrides (`load`) and written back as TOML and MLflow params."""

from __future__ import annotations

import difflib
import math
import os
import tomllib
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from linkevo.sim.errors import ConfigError
from linkevo.sim.robot.gait import GAIT_KEYS
from linkevo.sim.robot.hexapod import LEG_SLOTS, PHYSICS_KEYS, Robot
from linkevo.sim.study import (
    APPROACHES,
    DEFAULT_ANGLES,
    DEFAULT_BATCH,
    DEFAULT_WALK_BATCH,
    MAX_WALKS,
    MIN_ANGLES,
    MODES,
    SAIL_APPROACHES,
    SINGLE_FITNESSES,
    STUDY_APPROACHES,
    STUDY_EVALUATIONS,
    STUDY_FITNESSES,
    SURROGATES,
    TARGETS,
    WALKING_FITNESS,
    is_map_elites,
)
from linkevo.workers.store.outage import OUTAGE_LIMIT_S

STUDY_TRIALS = 10
"""Trials per approach and fitness in the study."""
MAX_TRIALS = 1000
"""The most trials per approach and fitness: a grid of the study's 14 cells at this many is
14,000 runs in the store (the study ran 10, its statistics 30)."""
MAX_NAME = 200
"""The longest experiment name (MLflow's stores keep at most 256 characters)."""
COUNT_LIMITS = {
    "trials": MAX_TRIALS,
    "max_concurrent_trials": 100_000,
    "max_retries": 100,
    "evaluators_per_trial": 1024,
    "checkpoint_every": 1_000_000,
    "n_angles": 3600,
    "walks": MAX_WALKS,
    "walk_batch": 100_000,
}
"""The largest value each count may take: counts are bounded before any work, so a slip
of the finger (`trials=1000000000`) is refused rather than expanded."""
MAX_ITERATIONS = 1_000_000
"""The most iterations (evaluations / batch_size) a trial may run: each logs a row of
metrics to MLflow and to metrics.csv, so a budget beyond it fills the store, not the
archive (the study runs 146)."""
BATCH_COPIES = 4
"""Copies of a batch a trial holds at once (its genomes and evaluation in the trial, the
evaluator and Ray's object store): the memory a batch needs is this many times
`sim.linkage.evaluation.evaluation_bytes`."""
MEMORY_SHARE = 0.5
"""The share of this machine's memory one trial's batch may need."""
EXECUTION_KEYS: frozenset[str] = frozenset(
    {
        "evaluators_per_trial",
        "cpus_per_evaluator",
        "trial_cpus",
        "checkpoint_every",
        "max_concurrent_trials",
        "max_retries",
        "server_outage_s",
        "experiment",
        "tracking_uri",
        "work_dir",
    }
)
"""Keys that say how and where a grid runs, not what it computes: left out of the grid id."""


@dataclass(frozen=True)
class GridConfig:
    """One grid: `trials` seeds of every (approach, fitness) cell, and how to run them.

    Attributes:
        trials: trials per (approach, fitness) cell, >= 1.
        approaches: search approaches, a subset of `APPROACHES` (default: the study's six,
            without the RANDOM baseline).
        fitnesses: fitness functions the trials optimise, a subset of `sim.study.SINGLE_FITNESSES`.
        evaluations: evaluation budget per trial, >= 1.
        batch_size: children per iteration (and the initial population), >= 1.
        mode: "paper" or "legacy".
        seed: grid seed every trial seed derives from, >= 0.
        target: named F_p target ("D16" or "D24").
        n_angles: crank angles simulated per linkage, >= 3.
        max_seconds: optional wall-clock budget per trial (seconds, > 0).
        options: per-approach option tables (`options["MAP-AU"] = {...}`) passed to that
            approach's optimizer (`algorithms.make_optimizer`).
        walk_rerank: at the end of each trial, walk its K lowest-loss linkages that pass
            the physical checks on the simulated robot (flat floor) and log the best walker
            (`workers.trial`, docs/walking.md); 0 (the default) walks none. Path
            fitnesses only.
        walks: the budget of each walking trial (fitness "Fw"): candidates walked on the
            simulated robot (`sim.robot.walk_fitness`), >= 1 when "Fw" is among `fitnesses`,
            else 0. `evaluations` does not apply to them (their guard is
            `sim.study.CANDIDATES_PER_WALK` candidates per walk).
        walk_batch: candidates per iteration (and initial population) of a walking
            trial, >= 1 (`batch_size` is the path fitnesses').
        seed_from: the warm start of the walking MAP-Elites trials: the run id of an
            earlier MAP-Elites trial in the same store with a walk map, whose walked cells
            make each trial's first batch (`workers.seed_repertoire`); "" (the default)
            for none.
        surrogate: how the walking MAP-Elites trials use the learned walk model: "screen"
            (or true) walks only the candidates the model, fitted on each trial's walks as
            it goes, predicts could enter or improve the archive (`workers.walk_surrogate`);
            "sail" runs each trial's search in the model and walks what it proposes (SAIL,
            `workers.walk_sail`; MAP-WH, MAP-LIS, MAP-ST); "" or false (the default) walks
            every candidate the search makes.
        walk_model: the SAIL trials' head start: the run id of a walk model in the same
            store (`linkevo walkmodel fit`), refitted with each trial's walks; "" (the
            default) for none.
        physics: the simulated robot's parameters that differ from the study's robot
            (`sim.robot.hexapod.Physics`; a `[physics]` table, as the robot config's, e.g. the
            one `linkevo hexapod calibrate` writes), for every walk of the grid's trials
            (fitness F_w, `walk_rerank`); empty (the default): the study's robot.
        gait: the gait's settings that differ from the study's (`sim.robot.gait.GaitConfig`;
            a `[gait]` table, as the robot config's), for the same walks; empty (the
            default): the study's gait. The legs keep the study's tripods.
        mounting: each slot's spacer layers between the frame and its leg (a `[mounting]`
            table, as the robot config's: all six slots); empty (the default): chosen for
            each linkage so that neighbouring legs cannot meet (`sim.robot.mounting`).
        evaluators_per_trial: evaluator actors per trial (K), >= 0; 0 (the default): the
            trial task evaluates its batches itself, with numba threads.
        cpus_per_evaluator: CPUs reserved by each evaluator actor, > 0.
        trial_cpus: CPUs reserved by the trial task itself: a number >= 0, or "auto"
            (the default): with K = 0 the cluster's CPUs shared out among the trials
            (`orchestrator.reservation`), with actors 0 (the trial loop shares the first
            evaluator's reservation; the two take turns).
        checkpoint_every: iterations between checkpoints, >= 1.
        max_concurrent_trials: trials in flight at once; 0 = as many as the cluster fits.
        max_retries: retries of a trial after a node, worker or actor loss, >= 0.
        server_outage_s: seconds a tracking server may stay silent before the grid stops
            (`workers.store.outage`), > 0.
        experiment: MLflow experiment name.
        tracking_uri: MLflow tracking URI; "" = the embedded store (or MLFLOW_TRACKING_URI).
        work_dir: folder for trial checkpoints; "" = next to the embedded store.
    """

    trials: int = STUDY_TRIALS
    approaches: tuple[str, ...] = STUDY_APPROACHES
    fitnesses: tuple[str, ...] = STUDY_FITNESSES
    evaluations: int = STUDY_EVALUATIONS
    batch_size: int = DEFAULT_BATCH
    mode: str = "paper"
    seed: int = 0
    target: str = "D16"
    n_angles: int = DEFAULT_ANGLES
    max_seconds: float | None = None
    options: dict[str, Any] = field(default_factory=dict)
    walk_rerank: int = 0
    walks: int = 0
    walk_batch: int = DEFAULT_WALK_BATCH
    seed_from: str = ""
    surrogate: str | bool = ""
    walk_model: str = ""
    physics: dict[str, float] = field(default_factory=dict)
    gait: dict[str, float] = field(default_factory=dict)
    mounting: dict[str, int] = field(default_factory=dict)
    evaluators_per_trial: int = 0
    cpus_per_evaluator: float = 1.0
    trial_cpus: float | str = "auto"
    checkpoint_every: int = 10
    max_concurrent_trials: int = 0
    max_retries: int = 3
    server_outage_s: float = OUTAGE_LIMIT_S
    experiment: str = "linkevo"
    tracking_uri: str = ""
    work_dir: str = ""

    def __post_init__(self) -> None:
        _validate(self)

    def to_dict(self) -> dict[str, Any]:
        """Returns the config as plain TOML/JSON-able values (lists, not tuples)."""
        out = asdict(self)
        for key, value in out.items():
            if isinstance(value, tuple):
                out[key] = list(value)
        if out["max_seconds"] is None:
            del out["max_seconds"]
        return out

    def identity(self) -> dict[str, Any]:
        """Returns the keys that determine the grid's results (what the grid id hashes).
        `walk_rerank`, `seed_from`, `surrogate`, `walk_model`, `physics`, `gait` and
        `mounting` count
        only when they are on, and `walks`
        and `walk_batch` only for a grid with walking trials, so grids without them keep
        their ids. `trials` does not
        count: a trial's seed depends on its index, not on how many the grid holds, so a
        grid with more trials extends one with fewer (`--resume`)."""
        out = {k: v for k, v in self.to_dict().items() if k not in EXECUTION_KEYS and k != "trials"}
        if not out["walk_rerank"]:
            del out["walk_rerank"]
        if WALKING_FITNESS not in self.fitnesses:
            del out["walks"], out["walk_batch"]
        if not out["seed_from"]:
            del out["seed_from"]
        if not out["surrogate"]:
            del out["surrogate"]
        elif out["surrogate"] == "screen":
            out["surrogate"] = True  # as linkevo hashed it before SAIL: screen grids keep ids
        if not out["walk_model"]:
            del out["walk_model"]
        for key in ("physics", "gait", "mounting"):
            if not out[key]:
                del out[key]
        return out


KEYS: tuple[str, ...] = tuple(f.name for f in fields(GridConfig))
MAX_WALK_RERANK = 1000
"""Walks per trial at most (about 7 minutes of one core)."""
FLOAT_KEYS: tuple[str, ...] = ("max_seconds", "cpus_per_evaluator", "trial_cpus", "server_outage_s")
"""Keys read as floats when the TOML gives an integer (`trial_cpus = 0`)."""


def _fail(key: str, value: object, allowed: str) -> ConfigError:
    return ConfigError(f"config key '{key}' = {value!r} is invalid: {allowed}")


def _check_int(cfg: GridConfig, key: str, minimum: int) -> None:
    value = getattr(cfg, key)
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise _fail(key, value, f"allowed: an integer >= {minimum}")


def _check_number(cfg: GridConfig, key: str, minimum: float, strict: bool) -> None:
    value = getattr(cfg, key)
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or value < minimum or (strict and value == minimum):
        bound = f"> {minimum}" if strict else f">= {minimum}"
        raise _fail(key, value, f"allowed: a finite number {bound}")


def machine_memory() -> int:
    """Returns this machine's memory in bytes."""
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def _check_size(cfg: GridConfig) -> None:
    """Refuses a budget or batch this machine cannot hold (`MAX_ITERATIONS`,
    `BATCH_COPIES`, `MEMORY_SHARE`), so a dry run catches it too."""
    from linkevo.sim.linkage.evaluation import evaluation_bytes

    if cfg.evaluations > cfg.batch_size * MAX_ITERATIONS:
        raise _fail(
            "evaluations",
            cfg.evaluations,
            f"allowed: at most batch_size x {MAX_ITERATIONS:,} = "
            f"{cfg.batch_size * MAX_ITERATIONS:,} (each iteration logs a row of metrics)",
        )
    need = BATCH_COPIES * evaluation_bytes(cfg.batch_size, cfg.n_angles)
    have = machine_memory()
    if need > MEMORY_SHARE * have:
        per_genome = BATCH_COPIES * evaluation_bytes(1, cfg.n_angles)
        largest = int(MEMORY_SHARE * have // per_genome)
        raise ConfigError(
            f"config keys 'batch_size' = {cfg.batch_size:,} and 'n_angles' = "
            f"{cfg.n_angles:,}: a batch needs about {need / 2**30:,.1f} GiB, more than half "
            f"of this machine's {have / 2**30:.1f} GiB; allowed at n_angles = "
            f"{cfg.n_angles:,}: batch_size <= {largest:,} (or fewer crank angles)"
        )


def _check_choices(cfg: GridConfig, key: str, allowed: tuple[str, ...], many: bool) -> None:
    value = getattr(cfg, key)
    items = value if many else (value,)
    if many and (not isinstance(value, tuple) or not value):
        raise _fail(key, value, f"allowed: a non-empty list drawn from {list(allowed)}")
    for item in items:
        if item not in allowed:
            raise _fail(key, item, f"allowed values: {', '.join(allowed)}")
    if many and len(set(items)) != len(items):
        raise _fail(key, list(value), "each value may appear only once")


def _validate(cfg: GridConfig) -> None:
    for key in ("trials", "evaluations", "batch_size", "checkpoint_every"):
        _check_int(cfg, key, 1)
    _check_int(cfg, "n_angles", MIN_ANGLES)
    for key in ("seed", "max_concurrent_trials", "max_retries", "evaluators_per_trial"):
        _check_int(cfg, key, 0)
    _check_int(cfg, "walks", 0)
    _check_int(cfg, "walk_batch", 1)
    for key, most in COUNT_LIMITS.items():
        if getattr(cfg, key) > most:
            raise _fail(key, getattr(cfg, key), f"allowed: at most {most:,}")
    _check_int(cfg, "walk_rerank", 0)
    if cfg.walk_rerank > MAX_WALK_RERANK:
        raise _fail("walk_rerank", cfg.walk_rerank, f"allowed: 0 to {MAX_WALK_RERANK}")
    _check_number(cfg, "cpus_per_evaluator", 0.0, strict=True)
    _check_number(cfg, "server_outage_s", 0.0, strict=True)
    if cfg.trial_cpus != "auto":
        try:
            _check_number(cfg, "trial_cpus", 0.0, strict=cfg.evaluators_per_trial == 0)
        except ConfigError:
            bound = "> 0 (the task evaluates itself)" if cfg.evaluators_per_trial == 0 else ">= 0"
            allowed = f'allowed: "auto" or a number {bound}'
            raise _fail("trial_cpus", cfg.trial_cpus, allowed) from None
    if cfg.max_seconds is not None:
        _check_number(cfg, "max_seconds", 0.0, strict=True)
    _check_size(cfg)
    _check_choices(cfg, "approaches", APPROACHES, many=True)
    _check_choices(cfg, "fitnesses", SINGLE_FITNESSES, many=True)
    walking = WALKING_FITNESS in cfg.fitnesses
    if walking and cfg.walks < 1:
        raise _fail(
            "walks",
            cfg.walks,
            "allowed: an integer >= 1 with fitness Fw (walked "
            "candidates per trial, e.g. --set walks=2000)",
        )
    if not walking and cfg.walks:
        raise _fail("walks", cfg.walks, 'allowed: 0 unless fitnesses holds "Fw"')
    if not isinstance(cfg.seed_from, str):
        raise _fail("seed_from", cfg.seed_from, "allowed: a run id (a string)")
    if isinstance(cfg.surrogate, bool):
        object.__setattr__(cfg, "surrogate", "screen" if cfg.surrogate else "")
    if cfg.surrogate not in SURROGATES:
        raise _fail(
            "surrogate", cfg.surrogate, 'allowed: "screen" (or true), "sail", "" (or false)'
        )
    if not isinstance(cfg.walk_model, str):
        raise _fail("walk_model", cfg.walk_model, "allowed: a walk model's run id (a string)")
    if cfg.walk_model and cfg.surrogate != "sail":
        raise _fail("walk_model", cfg.walk_model, 'allowed: with surrogate = "sail" only')
    if cfg.surrogate == "sail":
        others = [a for a in cfg.approaches if a not in SAIL_APPROACHES]
        if others:
            raise _fail(
                "surrogate",
                cfg.surrogate,
                f"allowed with approaches {', '.join(SAIL_APPROACHES)} (this grid has "
                f"{', '.join(others)}, whose descriptors are learned)",
            )
    not_maps = [a for a in cfg.approaches if not is_map_elites(a)]
    for key in ("seed_from", "surrogate"):  # walking MAP-Elites trials only
        if getattr(cfg, key) and (cfg.fitnesses != (WALKING_FITNESS,) or not_maps):
            raise _fail(
                key,
                getattr(cfg, key),
                'allowed: with fitnesses = ["Fw"] and MAP-Elites approaches only '
                f"(this grid has {', '.join(cfg.fitnesses)} and {', '.join(cfg.approaches)})",
            )
    for key, names in (("physics", PHYSICS_KEYS), ("gait", GAIT_KEYS), ("mounting", LEG_SLOTS)):
        table = getattr(cfg, key)
        if not isinstance(table, dict):
            raise _fail(key, table, f"allowed: a table of {', '.join(names)}")
        try:
            Robot.of({key: table})
        except (TypeError, ValueError) as exc:
            raise _fail(key, table, str(exc)) from None
    _check_choices(cfg, "mode", MODES, many=False)
    _check_choices(cfg, "target", TARGETS, many=False)
    for key in ("experiment", "tracking_uri", "work_dir"):
        if not isinstance(getattr(cfg, key), str):
            raise _fail(key, getattr(cfg, key), "allowed: a string")
    if not cfg.experiment or len(cfg.experiment) > MAX_NAME or not cfg.experiment.isprintable():
        shown = cfg.experiment if len(cfg.experiment) <= 40 else f"{cfg.experiment[:40]}..."
        raise _fail("experiment", shown, f"allowed: a name of 1 to {MAX_NAME} printable characters")
    if not isinstance(cfg.options, dict):
        raise _fail("options", cfg.options, "allowed: a table of per-approach option tables")
    for approach, table in cfg.options.items():
        if approach not in APPROACHES:
            raise _fail(f"options.{approach}", table, f"allowed tables: {', '.join(APPROACHES)}")
        if not isinstance(table, dict):
            raise _fail(f"options.{approach}", table, "allowed: a table of option = value")


def from_dict(data: dict[str, Any], source: str = "config") -> GridConfig:
    """Returns the GridConfig of a parsed TOML table; every key not given takes its default.

    Raises:
        ConfigError: naming an unknown key (with the closest known one) or a bad value.
    """
    unknown = [k for k in data if k not in KEYS]
    if unknown:
        key = unknown[0]
        close = difflib.get_close_matches(key, KEYS, n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise ConfigError(f"{source}: unknown key '{key}'{hint}; allowed keys: {', '.join(KEYS)}")
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in data.items()}
    for key in FLOAT_KEYS:
        value = values.get(key)
        if isinstance(value, int) and not isinstance(value, bool):
            values[key] = float(value)
    return GridConfig(**values)


def load(path: Path | str, overrides: list[str] | None = None) -> GridConfig:
    """Returns the GridConfig read from a TOML file with `--set` overrides applied.

    Raises:
        ConfigError: the file is missing or malformed TOML, or a key or value is bad.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read config file {str(path)!r}: {exc.strerror}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path}: not UTF-8 text (byte {exc.start} is {exc.object[exc.start]:#04x}); "
            "allowed: a TOML file saved as UTF-8"
        ) from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: malformed TOML: {exc}") from exc
    return from_dict(apply_overrides(data, overrides or []), source=str(path))


# The config as text: `--set key=value` overrides read and applied to a TOML table, the
# resolved config written back as TOML (`to_toml`, which `load` reads to an equal config)
# and flattened into MLflow params (`flatten`).


def parse_override(text: str) -> tuple[list[str], Any]:
    """Returns the dotted key path and TOML value of one `--set key=value` override.

    The value is read as a TOML value (`3`, `"EA"`, `["EA","MAP-LIS"]`, `true`); a bare
    word that is not valid TOML (`legacy`) is taken as a string.
    """
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
