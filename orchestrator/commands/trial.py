"""Provides `linkevo trial`: one search trial in this process, with a progress bar."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from linkevo.orchestrator.cli import CliError
from linkevo.orchestrator.commands import options
from linkevo.sim.robot.walk_rows import FLOOR_ORDER
from linkevo.sim.study import (
    APPROACHES,
    CANDIDATES_PER_WALK,
    DEFAULT_ANGLES,
    DEFAULT_BATCH,
    DEFAULT_WALK_BATCH,
    MIN_ANGLES,
    SINGLE_FITNESSES,
    WALKING_FITNESS,
)
from linkevo.workers.store.run_layout import CHECKPOINT_DIR, METRICS_FILE, PREDICTION_MAP

if TYPE_CHECKING:
    from linkevo.workers.trial_spec import TrialSpec


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `trial` subcommand."""
    parser = subparsers.add_parser(
        "trial",
        help="run one search trial in this process",
        description=(
            "Run one trial (ask -> evaluate -> tell) and write metrics.csv, the final "
            "population or repertoire, the best linkage (JSON, PNG) and settings.json to DIR."
        ),
    )
    parser.add_argument("--approach", required=True, help=f"one of {', '.join(APPROACHES)}")
    parser.add_argument("--fitness", required=True, help=f"one of {', '.join(SINGLE_FITNESSES)}")
    parser.add_argument(
        "--evaluations",
        type=int,
        default=None,
        help="evaluation budget (>= batch size); required but for --fitness Fw, where it "
        f"is a guard (default: {CANDIDATES_PER_WALK} candidates per walk)",
    )
    parser.add_argument(
        "--walks",
        type=int,
        default=None,
        help="--fitness Fw: the budget in candidates walked on the simulated robot",
    )
    parser.add_argument(
        "--surrogate",
        nargs="?",
        const="screen",
        choices=("screen", "sail"),
        help="--fitness Fw, a MAP-Elites approach: with the learned walk model, fitted on the "
        "trial's walks as it goes, 'screen' (alone: --surrogate) walks only the candidates "
        "it predicts could enter the archive; 'sail' runs the search in the model and walks "
        "what it proposes (MAP-WH, MAP-LIS, MAP-ST; writes prediction_map.parquet)",
    )
    parser.add_argument(
        "--walk-model",
        metavar="RUN_ID",
        help="--surrogate sail: start from this walk model of the store (linkevo walkmodel "
        "fit), refitted with the trial's walks",
    )
    options.store(parser)
    parser.add_argument(
        "--config",
        type=Path,
        default=None,
        help="robot TOML whose [physics], [gait] and motors' phases the walks of an Fw trial "
        "use ("
        "default: the study's robot, as the shipped configs/hexapod.toml)",
    )
    parser.add_argument(
        "--batch-size",
        type=int,
        default=None,
        help=f"children per iteration (default: {DEFAULT_BATCH}; Fw: {DEFAULT_WALK_BATCH})",
    )
    options.mode(parser)
    options.seed(parser)
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder")
    parser.add_argument("--resume", action="store_true", help="continue from DIR's checkpoint")
    options.target(parser)
    parser.add_argument(
        "--n-angles",
        type=int,
        default=DEFAULT_ANGLES,
        help=f"crank angles per turn (>= {MIN_ANGLES})",
    )
    parser.add_argument(
        "--checkpoint-every", type=int, default=10, help="iterations between checkpoints"
    )
    parser.add_argument("--max-seconds", type=float, default=None, help="wall-clock limit")
    parser.add_argument(
        "--option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="approach option (VALUE parsed as JSON when it can be), repeatable",
    )
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    parser.set_defaults(func=handle)


def parse_options(items: list[str]) -> dict[str, object]:
    """Returns `KEY=VALUE` items as a dict, VALUE parsed as JSON when possible."""
    options: dict[str, object] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise CliError(f"--option {item!r} must look like KEY=VALUE")
        try:
            options[key] = json.loads(raw)
        except json.JSONDecodeError:
            options[key] = raw
    return options


def check_out_dir(out: Path, resume: bool) -> None:
    """Checks that DIR can be written, and that it holds no trial unless resuming."""
    options.output_folder(out)
    if not resume and ((out / METRICS_FILE).exists() or (out / CHECKPOINT_DIR).exists()):
        raise CliError(
            f"output folder {str(out)!r} already holds a trial; pass --resume to continue it "
            "or choose another folder"
        )


def handle(args: argparse.Namespace) -> int:
    """Validates everything, runs the trial, prints where the results are."""
    from linkevo.workers.evaluators import make_evaluator
    from linkevo.workers.recorders import ProgressRecorder
    from linkevo.workers.store.artifacts import writer_lock
    from linkevo.workers.trial import run_trial

    spec = trial_spec(args)
    check_out_dir(args.out, args.resume)
    head_start = None
    if spec.walk_model:
        from linkevo.workers.store.runs import RunStore
        from linkevo.workers.store.walk_models import load_model

        head_start, _ = load_model(
            RunStore.open(args.tracking_uri, args.experiment), spec.walk_model
        )
    walking = spec.walking_trial
    with writer_lock(args.out, "linkevo trial"):  # one trial writes a folder at a time
        recorder = ProgressRecorder(
            spec.walks if walking else spec.evaluations,
            unit="walk" if walking else "eval",
            counter="walks" if walking else "evaluations",
            disable=args.no_progress,
        )
        try:
            with make_evaluator(spec, head_start=head_start) as evaluator:
                result = run_trial(spec, evaluator, recorder, args.out, resume=args.resume)
        finally:
            recorder.close()
    spent = f"{result.evaluations} evaluations"
    if walking:
        spent = f"{int(result.metrics['walks'])} walks ({result.evaluations} candidates)"
    print(
        f"{spec.approach} {spec.fitness}: best loss {result.best_loss:.4f} after {spent} "
        f"({result.iterations} iterations, {result.seconds:.1f} s, stopped by "
        f"{result.stopped_by}); files in {args.out}"
    )
    if "best_models_agree" in result.metrics:
        print(confirmation_line(result.metrics))
    if (args.out / PREDICTION_MAP).exists():
        print(prediction_map_line(args.out / PREDICTION_MAP))
    return 0


def prediction_map_line(path: Path) -> str:
    """A SAIL trial's prediction map in one line: its cells, how many were never walked,
    and how many of those it predicts to walk `WALKER_CM` on both floors without breaking
    (a break probability under one half on each, as the explorer reads it)."""
    import pandas as pd

    from linkevo.sim.robot.walk_rows import WALKER_CM

    table = pd.read_parquet(path)
    never = table[~table["walked"]]
    far = (never[[f"{f}_predicted_cm" for f in FLOOR_ORDER]] >= WALKER_CM).all(axis=1)
    sound = (never[[f"{f}_p_break" for f in FLOOR_ORDER]] < 0.5).all(axis=1)
    return (
        f"prediction map: {len(table)} cells, {len(never)} never walked, of which "
        f"{int((far & sound).sum())} predicted to walk {WALKER_CM:.0f} cm on both floors "
        f"without breaking ({path.name}; linkevo pull RUN_ID:CELL builds one)"
    )


def confirmation_line(metrics: dict[str, float]) -> str:
    """The best walker's walks on the full model in one line (`best_confirmed.json`)."""
    full = ", ".join(f"{f} {metrics[f'best_full_{f}_cm']:.1f} cm" for f in FLOOR_ORDER)
    verdict = "agrees" if metrics["best_models_agree"] else "DISAGREES with the lean model"
    chaos = "; a chaotic gait (its repeats disagree widely)" if metrics["best_chaotic"] else ""
    slides = (
        "; SLIDES: its feet slip at over half the body's speed" if metrics["best_slides"] else ""
    )
    return (
        f"best walker on the full model, 5 hand-placed starts per floor: {full} per 10 s; "
        f"{verdict}{chaos}{slides}; a leg {metrics['best_leg_width_cm']:.0f} cm wide, stroke "
        f"{metrics['best_stroke_cm']:.0f} cm, crank share {metrics['best_crank_share']:.2f} "
        "(best_confirmed.json)"
    )


def trial_spec(args: argparse.Namespace) -> TrialSpec:
    """Returns the trial the arguments describe, checked (`CliError` naming what is wrong)."""
    from linkevo.workers.trial_spec import TrialSpec, build_optimizer

    settings = dict(
        mode=args.mode,
        seed=args.seed,
        target=args.target,
        n_angles=args.n_angles,
        checkpoint_every=args.checkpoint_every,
        max_seconds=args.max_seconds,
        options=parse_options(args.option),
    )
    if args.config is not None:
        from linkevo.orchestrator.commands.hexapod import load_robot
        from linkevo.sim.robot.hexapod import ROBOT_PARTS

        robot = load_robot(args).robot().changed()
        settings |= {part: robot.get(part, {}) for part in ROBOT_PARTS}
    if args.batch_size is not None:
        settings["batch_size"] = args.batch_size
    try:
        if args.fitness == WALKING_FITNESS:
            if args.walks is None:
                raise CliError("--fitness Fw needs --walks N: its budget in walked candidates")
            if args.evaluations is not None:
                settings["evaluations"] = args.evaluations
            spec = TrialSpec.walking(
                args.approach,
                args.walks,
                surrogate=args.surrogate or "",
                walk_model=args.walk_model or "",
                **settings,
            )
        else:
            for given, option in (
                (args.walks is not None, "--walks"),
                (args.surrogate, "--surrogate"),
                (args.walk_model, "--walk-model"),
            ):
                if given:
                    raise CliError(
                        f"{option} is for --fitness Fw only (this trial is {args.fitness})"
                    )
            if args.evaluations is None:
                raise CliError(f"--fitness {args.fitness} needs --evaluations N")
            settings.setdefault("batch_size", DEFAULT_BATCH)
            spec = TrialSpec(args.approach, args.fitness, args.evaluations, **settings)
        build_optimizer(spec)
    except (ValueError, TypeError) as exc:  # an approach's options, checked by the optimizer
        raise CliError(str(exc)) from exc
    return spec
