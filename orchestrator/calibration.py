"""Provides `calibrate`: the simulated robot's chosen parameters fitted to a robot's own
recorded field trials (`linkevo hexapod trial`), with a held-out error by
cross-validation, written as a robot config every command takes (`--config`).

What is fitted: any of the `[physics]` parameters (`sim.robot.hexapod.PHYSICS_KEYS`) and the
gait's speed and gains (`FITTED_GAIT`). The loss is the mean squared difference, in cm²,
between each trial's measured mean distance and the distance the simulator walks the
same linkage on the same floor for the same seconds (the lean model, one walk from the
unperturbed start: deterministic, so the loss is a function of the parameters alone).
scipy's bounded Powell search minimises it over each parameter's allowed range, starting
from the base config's values; it needs no gradient, which a walk's contacts do not
have. Only real field trials are input: a simulated run (the emulator's, or `hexapod
simulate`'s) would fit the simulator to itself.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from linkevo.hardware.config import RobotConfig
from linkevo.sim.errors import LinkevoError
from linkevo.sim.linkage.linkage_doc import from_document
from linkevo.sim.robot.gait import GaitConfig
from linkevo.sim.robot.hexapod import FLOORS, PHYSICS_KEYS, Physics, floor
from linkevo.sim.robot.leg import leg_from_genome
from linkevo.sim.robot.walking import WalkSettings, walk
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.artifacts import read_document
from linkevo.workers.store.runs import NotFound

FITTED_GAIT: tuple[str, ...] = ("speed_rpm", "kp", "ki", "kd")
"""The gait's values a calibration may fit (`[gait]` of the robot config)."""
CALIBRATED: tuple[str, ...] = (*PHYSICS_KEYS, *FITTED_GAIT)
"""Every name `--params` accepts."""
MAX_FOLDS = 10


class CalibrationError(LinkevoError):
    """The calibration cannot run as asked; says why before any walk."""


@dataclass(frozen=True)
class FieldTrial:
    """One recorded field trial: the linkage walked, where, for how long, how far."""

    run_id: str
    document: dict
    floor: str
    seconds: float
    distance_cm: float


@dataclass(frozen=True)
class Calibration:
    """A calibration's outcome.

    Attributes:
        values: the fitted value of each parameter, by name.
        start: each parameter's value in the base config.
        rmse_cm: the fitted simulator's root-mean-square error over every trial.
        rmse_start_cm: the base config's, over the same trials.
        heldout_rmse_cm: the error on trials left out of the fit (k-fold), NaN with one
            trial.
        folds: k of the cross-validation.
        predicted_cm: the fitted simulator's distance per trial (T,).
        measured_cm: each trial's measured mean distance (T,).
        walks: walks simulated in all.
    """

    values: dict[str, float]
    start: dict[str, float]
    rmse_cm: float
    rmse_start_cm: float
    heldout_rmse_cm: float
    folds: int
    predicted_cm: tuple[float, ...]
    measured_cm: tuple[float, ...]
    walks: int


def read_field_trials(store, run_ids: list[str]) -> list[FieldTrial]:
    """Returns the named runs as field trials, refusing any that is not a real field trial.

    Raises:
        CalibrationError: naming the run and why (not a field trial, simulated, no
            distances, no linkage).
    """
    trials = []
    for run_id in run_ids:
        try:
            run = store.run(run_id)
        except NotFound as exc:
            raise CalibrationError(f"--trials {run_id}: no such run in {store.uri}") from exc
        tags, params = run.data.tags, run.data.params
        if tags.get(layout.KIND) != layout.FIELD_TRIAL:
            raise CalibrationError(f"--trials {run_id}: not a field trial (linkevo hexapod trial)")
        if params.get(layout.SIMULATED, layout.REAL) != layout.REAL:
            raise CalibrationError(
                f"--trials {run_id}: a simulated field trial (simulated = "
                f"{params[layout.SIMULATED]}); allowed: trials walked by the real robot only"
            )
        if tags.get(layout.FLOOR) not in FLOORS:
            raise CalibrationError(
                f"--trials {run_id}: walked on the floor {tags.get(layout.FLOOR)!r}, which the "
                f"simulator does not model; allowed: trials on {', '.join(FLOORS)}"
            )
        history = store.metric_history(run_id, layout.DISTANCE_CM)
        if not history:
            raise CalibrationError(f"--trials {run_id}: the field trial has no distances")
        with tempfile.TemporaryDirectory() as tmp:
            document = read_document(store.download(run_id, layout.LINKAGE_JSON, Path(tmp)))
        trials.append(
            FieldTrial(
                run_id=run_id,
                document=document,
                floor=tags.get(layout.FLOOR, ""),
                seconds=float(params.get(layout.SECONDS, "10")),
                distance_cm=float(np.mean(list(history.values()))),
            )
        )
    return trials


def with_values(config: RobotConfig, values: dict[str, float]) -> RobotConfig:
    """Returns the config with the named physics and gait values replaced (checked by
    `Physics`' ranges; gait values by `GaitConfig`'s through the config loader)."""
    physics = {k: v for k, v in values.items() if k in PHYSICS_KEYS}
    gait = {k: v for k, v in values.items() if k in FITTED_GAIT}
    return dataclasses.replace(
        config,
        physics=dataclasses.replace(config.physics, **physics),
        gait=dataclasses.replace(config.gait, **gait),
    )


def bounds(name: str) -> tuple[float, float]:
    """Returns the range a parameter is searched over: its allowed range (a gait gain
    has no upper limit in the config; it is searched up to 10 times its default)."""
    cls = Physics if name in PHYSICS_KEYS else GaitConfig
    field = next(f for f in dataclasses.fields(cls) if f.name == name)
    low, high = field.metadata.get("low"), field.metadata.get("high")
    default = field.default
    return (0.0 if low is None else float(low)), (10.0 * default if high is None else high)


def simulated_cm(config: RobotConfig, trials: list[FieldTrial]) -> np.ndarray:
    """Returns (T,) the distance the simulator walks each trial's linkage, in cm."""
    robot = config.robot()
    out = []
    for trial in trials:
        leg = leg_from_genome(*from_document(trial.document))
        w = walk(leg, floor(trial.floor), settings=WalkSettings(seconds=trial.seconds), robot=robot)
        out.append(w.distance_m * 100.0 if math.isfinite(w.distance_m) else 0.0)
    return np.array(out)


def fit(
    config: RobotConfig,
    trials: list[FieldTrial],
    names: list[str],
    progress: Callable[[str], None] = lambda _: None,
) -> tuple[dict[str, float], int]:
    """Returns the parameters' values that minimise the squared error over `trials`, and
    the walks it took (module docstring)."""
    from scipy.optimize import minimize

    measured = np.array([t.distance_cm for t in trials])
    ranges = np.array([bounds(n) for n in names])
    start = np.array([current(config, n) for n in names])
    span = ranges[:, 1] - ranges[:, 0]
    walks = 0

    def loss(unit: np.ndarray) -> float:
        nonlocal walks
        values = dict(zip(names, ranges[:, 0] + np.clip(unit, 0, 1) * span, strict=True))
        walks += len(trials)
        return float(np.mean((simulated_cm(with_values(config, values), trials) - measured) ** 2))

    result = minimize(
        loss,
        (start - ranges[:, 0]) / span,
        method="Powell",
        bounds=[(0.0, 1.0)] * len(names),
        options={"xtol": 1e-3, "ftol": 1e-4, "maxfev": 60 * len(names)},
    )
    values = dict(zip(names, (ranges[:, 0] + np.clip(result.x, 0, 1) * span).tolist(), strict=True))
    progress(f"fitted {json.dumps({k: round(v, 4) for k, v in values.items()})}: {walks} walks")
    return values, walks


def current(config: RobotConfig, name: str) -> float:
    """Returns a parameter's value in the config."""
    return float(getattr(config.physics if name in PHYSICS_KEYS else config.gait, name))


def calibrate(
    config: RobotConfig,
    trials: list[FieldTrial],
    names: list[str],
    folds: int = 5,
    progress: Callable[[str], None] = print,
) -> Calibration:
    """Fits `names` to every trial, and measures the error on held-out trials by k-fold
    cross-validation (k = min(`folds`, trials); trials dealt to folds in order; with one
    trial there is no held-out error, NaN).

    Raises:
        CalibrationError: an unknown parameter name, or none.
    """
    unknown = [n for n in names if n not in CALIBRATED]
    if unknown or not names:
        raise CalibrationError(
            f"--params {','.join(names)}: {', '.join(unknown) or 'none given'} not allowed; "
            f"allowed: {', '.join(CALIBRATED)}"
        )
    measured = np.array([t.distance_cm for t in trials])
    k = min(folds, len(trials))
    errors = []
    walks = 0
    for fold in range(k if k >= 2 else 0):
        held = [i for i in range(len(trials)) if i % k == fold]
        kept = [t for i, t in enumerate(trials) if i % k != fold]
        values, n = fit(config, kept, names)
        walks += n
        predicted = simulated_cm(with_values(config, values), [trials[i] for i in held])
        errors += list(predicted - measured[held])
        progress(
            f"fold {fold + 1} of {k}: held-out errors {np.round(predicted - measured[held], 1)} cm"
        )
    values, n = fit(config, trials, names, progress)
    fitted = simulated_cm(with_values(config, values), trials)
    start = simulated_cm(config, trials)
    return Calibration(
        values=values,
        start={n: current(config, n) for n in names},
        rmse_cm=float(np.sqrt(np.mean((fitted - measured) ** 2))),
        rmse_start_cm=float(np.sqrt(np.mean((start - measured) ** 2))),
        heldout_rmse_cm=float(np.sqrt(np.mean(np.square(errors)))) if errors else math.nan,
        folds=k if k >= 2 else 0,
        predicted_cm=tuple(fitted.tolist()),
        measured_cm=tuple(measured.tolist()),
        walks=walks + n + 2 * len(trials),
    )


def config_text(base_text: str, config: RobotConfig, result: Calibration, note: str) -> str:
    """Returns the base config's TOML with its `[physics]` values and the fitted gait values
    replaced by the calibrated config's (comments kept; `[physics]` written last, under
    `note`)."""
    fitted = with_values(config, result.values)
    gait = [k for k in FITTED_GAIT if k in result.values]
    section, out = "", []
    for line in base_text.splitlines():
        stripped = line.strip()
        key = stripped.split("=", 1)[0].strip() if "=" in stripped else ""
        if stripped.startswith("["):
            section = stripped.split("#", 1)[0].strip()
            if section == "[physics]":
                continue
            out.append(line)
            if section == "[gait]":
                out += [f"{k} = {getattr(fitted.gait, k)!r}  # calibrated" for k in gait]
            continue
        if (section == "[physics]" and key) or (section == "[gait]" and key in gait):
            continue
        out.append(line)
    physics = [f"[physics]  # {note}"] + [
        f"{name} = {getattr(fitted.physics, name)!r}"
        + ("  # calibrated" if name in result.values else "")
        for name in PHYSICS_KEYS
    ]
    return "\n".join(out).rstrip() + "\n\n" + "\n".join(physics) + "\n"
