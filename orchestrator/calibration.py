"""Provides `calibrate`: the simulated robot's chosen parameters fitted to a robot's own
recorded field trials (`linkevo hexapod trial`), with what the trials can and cannot tell,
written as a robot config every command takes (`--config`).

What is fitted: any of the `[physics]` parameters (`sim.robot.hexapod.PHYSICS_KEYS`) and the gait's
speed and gains (`FITTED_GAIT`). The loss is the mean squared difference, in cm², between each
trial's measured mean distance and the distance the simulator walks the same linkage on the same
floor for the same seconds (the lean model, one walk from the unperturbed start: deterministic, so
the loss is a function of the parameters alone). The search is global, then local: the loss at the
base config's values and at `SOBOL_POINTS` points spread over the allowed ranges (a Sobol sample),
then scipy's bounded Powell search from the best of them; a walk's contacts give no gradient, and
one local search stops in the first minimum it meets.

What it tells: each parameter's **profile** (the loss along its range, the others at
their fitted values) and from it a 95 % interval, where the loss stays within what the
trials' own noise allows (`interval_rise`). A parameter whose interval is wider than
`IDENTIFIED_SHARE` of its value either way is **not identified** by these trials: it stays at the
base config's value and is not written as calibrated; the others are fitted again with
it held. The **prediction error** is measured on legs the fit never saw: the trials are
dealt to folds by leg (a fold holds whole legs, every floor they walked), one leg per fold
(leave-one-leg-out) unless `folds` says fewer, and each fold's legs are predicted by the
fit on the others; beside it, the same legs' error with the base config (no calibration).
Only real field trials are input: a simulated run (the emulator's, or `hexapod simulate`'s)
would fit the simulator to itself.
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
SOBOL_POINTS = 4
"""The global search's points besides the base config's values: a Sobol sample of the
ranges (a power of two, for the sample's balance)."""
PROFILE_SHARES: tuple[float, ...] = (0.5, 0.75, 0.9, 1.0, 1.1, 1.25, 1.5)
"""A parameter's profile is the loss at these multiples of its fitted value (within its
range)."""
IDENTIFIED_SHARE = 0.25
"""A parameter is identified when moving it by this share of its value, either way, costs
more than the trials' noise can explain (its 95 % interval lies within ± this share)."""
NOISE_CM = 0.7
"""The measurement noise of a trial's mean distance (cm, one standard deviation) where its
repeats do not say: a hand-measured distance to the nearest half centimetre, and how a
robot set down by hand varies (about half a centimetre, docs/walking.md)."""


class CalibrationError(LinkevoError):
    """The calibration cannot run as asked; says why before any walk."""


@dataclass(frozen=True)
class FieldTrial:
    """One recorded field trial: the linkage walked, where, for how long, how far, and the
    noise of that mean (`NOISE_CM` where its repeats do not say)."""

    run_id: str
    document: dict
    floor: str
    seconds: float
    distance_cm: float
    noise_cm: float = NOISE_CM

    @property
    def leg(self) -> str:
        """What identifies the trial's leg (its genome and mode)."""
        return json.dumps([self.document.get("mode", "paper"), self.document.get("genome")])


@dataclass(frozen=True)
class Profile:
    """One parameter's profile: the loss along its searched range with the others held at
    their fitted values.

    Attributes:
        values: (P,) the parameter's values, the fitted one among them.
        loss: (P,) the loss at each (cm²).
        interval: the 95 % interval: the values whose loss stays within `interval_rise` of
            the least.
        identified: the interval lies within `IDENTIFIED_SHARE` of the fitted value either
            way.
    """

    values: tuple[float, ...]
    loss: tuple[float, ...]
    interval: tuple[float, float]
    identified: bool


@dataclass(frozen=True)
class Calibration:
    """A calibration's outcome.

    Attributes:
        values: the calibrated value of each identified parameter, by name.
        start: each asked parameter's value in the base config.
        profiles: each asked parameter's profile, by name.
        rmse_cm: the fitted simulator's root-mean-square error over every trial.
        rmse_start_cm: the base config's, over the same trials.
        heldout_rmse_cm: the prediction error: the error on legs left out of the fit (by
            leg, `calibrate`), NaN with one leg.
        heldout_start_cm: the base config's error on the same legs (no calibration).
        heldout_by_leg: each held-out leg's error (cm), by the first trial run of the leg.
        folds: the folds (legs per fold: all of one leg's trials).
        predicted_cm: the fitted simulator's distance per trial (T,).
        measured_cm: each trial's measured mean distance (T,).
        walks: walks simulated in all.
    """

    values: dict[str, float]
    start: dict[str, float]
    profiles: dict[str, Profile]
    rmse_cm: float
    rmse_start_cm: float
    heldout_rmse_cm: float
    heldout_start_cm: float
    heldout_by_leg: dict[str, float]
    folds: int
    predicted_cm: tuple[float, ...]
    measured_cm: tuple[float, ...]
    walks: int

    @property
    def identified(self) -> list[str]:
        """The parameters the trials identify (written as calibrated)."""
        return [n for n, p in self.profiles.items() if p.identified]

    @property
    def unidentified(self) -> list[str]:
        """The parameters the trials do not identify (left at the base config's values)."""
        return [n for n, p in self.profiles.items() if not p.identified]


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
                noise_cm=_noise(list(history.values())),
            )
        )
    return trials


def _noise(distances: list[float]) -> float:
    """The noise of a mean of repeats: their standard error, or `NOISE_CM` with one repeat
    (or repeats that agree to the digit)."""
    if len(distances) < 2 or np.std(distances) == 0:
        return NOISE_CM
    return float(np.std(distances, ddof=1) / math.sqrt(len(distances)))


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


class _Loss:
    """The mean squared error of the simulator over trials, as a function of some
    parameters' values in [0, 1] of their ranges; counts the walks."""

    def __init__(self, config: RobotConfig, trials: list[FieldTrial], names: list[str]):
        self.config, self.trials, self.names = config, trials, names
        self.ranges = np.array([bounds(n) for n in names]).reshape(-1, 2)
        self.measured = np.array([t.distance_cm for t in trials])
        self.walks = 0

    def values(self, unit: np.ndarray) -> dict[str, float]:
        span = self.ranges[:, 1] - self.ranges[:, 0]
        real = self.ranges[:, 0] + np.clip(unit, 0, 1) * span
        return dict(zip(self.names, real.tolist(), strict=True))

    def unit(self, values: dict[str, float]) -> np.ndarray:
        real = np.array([values[n] for n in self.names])
        return (real - self.ranges[:, 0]) / (self.ranges[:, 1] - self.ranges[:, 0])

    def __call__(self, unit: np.ndarray) -> float:
        self.walks += len(self.trials)
        walked = simulated_cm(with_values(self.config, self.values(unit)), self.trials)
        return float(np.mean((walked - self.measured) ** 2))


def fit(
    config: RobotConfig,
    trials: list[FieldTrial],
    names: list[str],
    progress: Callable[[str], None] = lambda _: None,
) -> tuple[dict[str, float], int]:
    """Returns the parameters' values that minimise the squared error over `trials`, and
    the walks it took: the best of the config's values and `SOBOL_POINTS` points of a
    Sobol sample of the ranges, then a bounded Powell search from it (module docstring)."""
    from scipy.optimize import minimize
    from scipy.stats import qmc

    loss = _Loss(config, trials, names)
    here = loss.unit({n: current(config, n) for n in names})
    sample = qmc.Sobol(len(names), scramble=True, seed=0).random(SOBOL_POINTS)
    points = np.vstack([here, sample])
    scores = [loss(x) for x in points]
    best = points[int(np.argmin(scores))]
    result = minimize(
        loss,
        best,
        method="Powell",
        bounds=[(0.0, 1.0)] * len(names),
        options={"xtol": 2e-3, "ftol": 1e-4, "maxfev": 25 * len(names)},
    )
    x = result.x if result.fun <= min(scores) else best
    values = loss.values(x)
    shown = json.dumps({k: round(v, 4) for k, v in values.items()})
    progress(f"fitted {shown}: {loss.walks} walks")
    return values, loss.walks


def interval_rise(trials: list[FieldTrial]) -> float:
    """Returns how far above its least the loss (a mean of squared errors, cm²) may rise
    within a 95 % interval of one parameter: 3.84 times the trials' mean noise variance.

    A likelihood-ratio interval would divide by the number of trials; a walk's distance is
    not smooth in the parameters (contacts make it rough at the scale of tenths of a cm²,
    which the least of a profile sits in), so the interval takes one trial's noise, not
    the mean's: a parameter is identified when moving it costs more than one trial's noise
    can explain."""
    noise = np.mean([t.noise_cm**2 for t in trials])
    return 3.84 * float(noise)


def profile(
    config: RobotConfig, trials: list[FieldTrial], fitted: dict[str, float], name: str
) -> tuple[Profile, int]:
    """Returns one parameter's profile around the fitted values (`Profile`) and its walks:
    the loss at `PROFILE_SHARES` of its fitted value, the others held."""
    loss = _Loss(
        with_values(config, {k: v for k, v in fitted.items() if k != name}), trials, [name]
    )
    low, high = loss.ranges[0]
    value = fitted[name]
    values = np.unique(np.clip(value * np.array(PROFILE_SHARES), low, high))
    losses = np.array([loss(loss.unit({name: v})) for v in values])
    inside = values[losses <= losses.min() + interval_rise(trials)]
    interval = (float(inside.min()), float(inside.max()))
    near = (1 - IDENTIFIED_SHARE) * value, (1 + IDENTIFIED_SHARE) * value
    found = Profile(
        values=tuple(values.tolist()),
        loss=tuple(losses.tolist()),
        interval=interval,
        identified=bool(near[0] <= interval[0] and interval[1] <= near[1]),
    )
    return found, loss.walks


def leg_folds(trials: list[FieldTrial], folds: int | None = None) -> list[list[int]]:
    """Returns the trials' indices dealt to folds by leg (every fold holds whole legs, all
    their floors): one leg per fold, or the legs dealt in turn to `folds` folds."""
    legs: dict[str, list[int]] = {}
    for i, trial in enumerate(trials):
        legs.setdefault(trial.leg, []).append(i)
    groups = list(legs.values())
    k = len(groups) if folds is None else min(folds, len(groups))
    return [[i for g in groups[f::k] for i in g] for f in range(k)]


def current(config: RobotConfig, name: str) -> float:
    """Returns a parameter's value in the config."""
    return float(getattr(config.physics if name in PHYSICS_KEYS else config.gait, name))


def calibrate(
    config: RobotConfig,
    trials: list[FieldTrial],
    names: list[str],
    folds: int | None = None,
    progress: Callable[[str], None] = print,
) -> Calibration:
    """Fits `names` to every trial, profiles each (parameters the trials do not identify
    are held at the base config's values and the rest fitted again), and measures the
    prediction error on legs left out (module docstring; `folds`: at most this many folds,
    default one per leg; with one leg there is no held-out error, NaN).

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
    values, walks = fit(config, trials, names, progress)
    profiles = {}
    for name in names:
        profiles[name], n = profile(config, trials, values, name)
        walks += n
        state = "identified" if profiles[name].identified else "NOT identified"
        low, high = profiles[name].interval
        progress(f"{name}: {state}, 95 % interval [{low:.4g}, {high:.4g}]")
    kept = [n for n in names if profiles[n].identified]
    if kept != names:  # the unidentified stay at the base config's values
        values, n = fit(config, trials, kept, progress) if kept else ({}, 0)
        walks += n
    errors, baseline, by_leg = [], [], {}
    split = leg_folds(trials, folds)
    for fold, held in enumerate(split if len(split) >= 2 else []):
        kept_trials = [t for i, t in enumerate(trials) if i not in held]
        fold_values, n = fit(config, kept_trials, kept) if kept else ({}, 0)
        out = [trials[i] for i in held]
        predicted = simulated_cm(with_values(config, fold_values), out) - measured[held]
        base = simulated_cm(config, out) - measured[held]
        walks += n + 2 * len(held)
        errors += predicted.tolist()
        baseline += base.tolist()
        by_leg[out[0].run_id] = float(np.sqrt(np.mean(predicted**2)))
        progress(f"fold {fold + 1} of {len(split)}: held-out errors {np.round(predicted, 1)} cm")
    fitted = simulated_cm(with_values(config, values), trials)
    start = simulated_cm(config, trials)

    def rms(values: list[float]) -> float:
        return float(np.sqrt(np.mean(np.square(values)))) if values else math.nan

    return Calibration(
        values=values,
        start={n: current(config, n) for n in names},
        profiles=profiles,
        rmse_cm=float(np.sqrt(np.mean((fitted - measured) ** 2))),
        rmse_start_cm=float(np.sqrt(np.mean((start - measured) ** 2))),
        heldout_rmse_cm=rms(errors),
        heldout_start_cm=rms(baseline),
        heldout_by_leg=by_leg,
        folds=len(split) if len(split) >= 2 else 0,
        predicted_cm=tuple(fitted.tolist()),
        measured_cm=tuple(measured.tolist()),
        walks=walks + 2 * len(trials),
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
