"""Provides `linkevo hexapod calibrate`: the simulator fitted to a robot's field trials."""

from __future__ import annotations

import argparse
from pathlib import Path

from linkevo.orchestrator.cli import CliError
from linkevo.orchestrator.commands import options
from linkevo.orchestrator.commands.hexapod import load_robot


def register(sub: argparse._SubParsersAction) -> None:
    """Adds `hexapod calibrate` to the hexapod group."""
    parser = sub.add_parser(
        "calibrate",
        help="fit the simulated robot's parameters to your robot's recorded field trials",
        description=(
            "Fits the chosen parameters of the simulated robot (its [physics]: frame, motor, "
            "floors; and the gait's speed and gains) to the distances a real robot walked in "
            "its recorded field trials (`linkevo hexapod trial`; simulated runs are refused), "
            "by walking each trial's linkage on its floor in the simulator and minimising the "
            "squared error (scipy's bounded Powell search). Reports the error before and "
            "after and on held-out trials (k-fold cross-validation), and writes the base "
            "config with the fitted values as a new robot TOML that `hexapod simulate`, "
            "`study`, `walkmap` and `trial --fitness Fw` take with --config "
            "(docs/walking.md, 'Calibration')."
        ),
    )
    parser.add_argument(
        "--trials",
        required=True,
        nargs="+",
        metavar="RUN_ID",
        help="the real field trials' run ids (`linkevo hexapod table` lists them)",
    )
    parser.add_argument(
        "--params",
        required=True,
        help="comma-separated names to fit: any key of the robot config's [physics] "
        "(frame_mass_kg, flat_friction, ...) or the gait's speed_rpm, kp, ki, kd",
    )
    parser.add_argument(
        "--out", required=True, type=Path, help="the calibrated robot config to write (.toml)"
    )
    options.force(parser)
    parser.add_argument(
        "--folds",
        type=options.count(2, 10),
        default=None,
        help="at most this many folds of whole legs (default: one leg per fold, leave-one-leg-out)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    options.robot_config(parser)
    options.store(parser)
    parser.set_defaults(func=handle)


def handle(args: argparse.Namespace) -> int:
    """Reads the trials, fits, writes the calibrated config and prints the errors."""
    import json
    import tomllib

    from linkevo.hardware.config import parse_config
    from linkevo.orchestrator.calibration import (
        CALIBRATED,
        calibrate,
        config_text,
        read_field_trials,
    )
    from linkevo.workers.store.artifacts import write_text_atomic
    from linkevo.workers.store.runs import RunStore

    names = [n.strip() for n in args.params.split(",") if n.strip()]
    bad = [n for n in names if n not in CALIBRATED]
    if bad or not names or len(set(names)) != len(names):
        raise CliError(
            f"--params {args.params!r}: {', '.join(bad) or 'each name once'}; allowed: "
            f"{', '.join(CALIBRATED)}"
        )
    options.output_file(args.out, force=args.force, suffix=".toml")
    if len(set(args.trials)) != len(args.trials) or len(args.trials) < 2:
        raise CliError(
            f"--trials: {len(args.trials)} given; allowed: at least 2 distinct runs of at "
            "least two legs (a fit, and an error on a leg the fit did not see)"
        )
    from linkevo.configs import shipped

    config = load_robot(args)
    base = args.config or shipped("hexapod.toml")
    store = RunStore.open(args.tracking_uri, args.experiment)
    trials = read_field_trials(store, args.trials)
    if len({t.leg for t in trials}) < 2:
        raise CliError(
            "--trials: every trial walked the same leg; allowed: trials of at least two legs "
            "(the prediction error is measured on a leg the fit did not see)"
        )
    say = (lambda _: None) if args.json else print
    result = calibrate(config, trials, names, folds=args.folds, progress=say)
    by_leg = ", ".join(f"{v:.1f}" for v in result.heldout_by_leg.values())
    note = (
        f"calibrated by linkevo hexapod calibrate from {len(trials)} field trials of "
        f"{result.folds} legs; identified: {', '.join(result.identified) or 'none'}; not "
        f"identified (left as they were): {', '.join(result.unidentified) or 'none'}; "
        f"prediction error on legs the fit did not see {result.heldout_rmse_cm:.1f} cm RMS "
        f"(by leg: {by_leg}; {result.heldout_start_cm:.1f} cm uncalibrated)"
    )
    text = config_text(Path(base).read_text(encoding="utf-8"), config, result, note)
    written = parse_config(tomllib.loads(text), str(args.out))
    for name, value in result.values.items():
        section = written.physics if hasattr(written.physics, name) else written.gait
        if getattr(section, name) != value:
            raise CliError(f"the base config {base} has no [gait] section to hold {name}")
    write_text_atomic(args.out, text)
    report = {
        "config": str(args.out),
        "params": result.values,
        "start": result.start,
        "identified": result.identified,
        "not_identified": result.unidentified,
        "intervals": {n: list(p.interval) for n, p in result.profiles.items()},
        "rmse_cm": round(result.rmse_cm, 2),
        "rmse_start_cm": round(result.rmse_start_cm, 2),
        "heldout_rmse_cm": round(result.heldout_rmse_cm, 2),
        "heldout_start_cm": round(result.heldout_start_cm, 2),
        "heldout_by_leg": {k: round(v, 2) for k, v in result.heldout_by_leg.items()},
        "folds": result.folds,
        "trials": len(trials),
        "walks": result.walks,
        "per_trial": [
            {
                "run_id": t.run_id,
                "floor": t.floor,
                "measured_cm": round(m, 2),
                "fitted_cm": round(f, 2),
            }
            for t, m, f in zip(trials, result.measured_cm, result.predicted_cm, strict=True)
        ],
    }
    if args.json:
        print(json.dumps(report))
        return 0
    for name, found in result.profiles.items():
        low, high = found.interval
        if found.identified:
            print(
                f"  {name}: {result.start[name]:g} -> {result.values[name]:.4g} "
                f"(95 % interval {low:.4g} to {high:.4g})"
            )
        else:
            print(
                f"  {name}: not identified by these trials (anything from {low:.4g} to "
                f"{high:.4g} fits them); left at {result.start[name]:g}"
            )
    print(
        f"RMSE over {len(trials)} trials: {result.rmse_start_cm:.1f} cm before, "
        f"{result.rmse_cm:.1f} cm fitted; on legs the fit did not see (leave-one-leg-out, "
        f"{result.folds} legs): {result.heldout_rmse_cm:.1f} cm, "
        f"{result.heldout_start_cm:.1f} cm uncalibrated"
    )
    print(f"config: {args.out} (give it with --config)")
    return 0
