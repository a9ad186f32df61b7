"""Provides `linkevo trial`: one search trial in this process, with a progress bar."""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path

from linkevo.orchestrator.cli import CliError
from linkevo.sim.study import (
    APPROACHES,
    DEFAULT_ANGLES,
    DEFAULT_BATCH,
    MIN_ANGLES,
    MODES,
    SINGLE_FITNESSES,
)
from linkevo.workers.store.run_layout import CHECKPOINT_DIR, METRICS_FILE


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
        "--evaluations", required=True, type=int, help="evaluation budget (>= batch size)"
    )
    parser.add_argument(
        "--batch-size", type=int, default=DEFAULT_BATCH, help="children per iteration"
    )
    parser.add_argument("--mode", default="paper", help=f"one of {', '.join(MODES)}")
    parser.add_argument("--seed", type=int, default=0, help="random seed (>= 0)")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder")
    parser.add_argument("--resume", action="store_true", help="continue from DIR's checkpoint")
    parser.add_argument("--target", default="D16", help="F_p target: D16, D24 or a JSON file")
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
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".write-test."):
            pass
    except OSError as exc:
        raise CliError(f"output folder {str(out)!r} is not writable: {exc.strerror}") from exc
    if not os.access(out, os.W_OK | os.X_OK):
        raise CliError(f"output folder {str(out)!r} is not writable")
    if not resume and ((out / METRICS_FILE).exists() or (out / CHECKPOINT_DIR).exists()):
        raise CliError(
            f"output folder {str(out)!r} already holds a trial; pass --resume to continue it "
            "or choose another folder"
        )


def handle(args: argparse.Namespace) -> int:
    """Validates everything, runs the trial, prints where the results are."""
    from linkevo.workers.evaluators import LocalEvaluator
    from linkevo.workers.recorders import ProgressRecorder
    from linkevo.workers.trial import run_trial
    from linkevo.workers.trial_spec import TrialSpec, build_optimizer

    try:
        spec = TrialSpec(
            approach=args.approach,
            fitness=args.fitness,
            evaluations=args.evaluations,
            batch_size=args.batch_size,
            mode=args.mode,
            seed=args.seed,
            target=args.target,
            n_angles=args.n_angles,
            checkpoint_every=args.checkpoint_every,
            max_seconds=args.max_seconds,
            options=parse_options(args.option),
        )
        build_optimizer(spec)
    except (ValueError, TypeError) as exc:  # an approach's options, checked by the optimizer
        raise CliError(str(exc)) from exc
    check_out_dir(args.out, args.resume)
    evaluator = LocalEvaluator(spec.eval_fitness, spec.mode, spec.target, spec.n_angles)
    recorder = ProgressRecorder(spec.evaluations, disable=args.no_progress)
    try:
        result = run_trial(spec, evaluator, recorder, args.out, resume=args.resume)
    finally:
        recorder.close()
    print(
        f"{spec.approach} {spec.fitness}: best loss {result.best_loss:.4f} after "
        f"{result.evaluations} evaluations ({result.iterations} iterations, "
        f"{result.seconds:.1f} s, stopped by {result.stopped_by}); files in {args.out}"
    )
    return 0
