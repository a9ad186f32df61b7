"""Provides `linkevo walkmodel`: fit the learned walk model on the store's walk maps, and
predict every cell of repertoires with it."""

from __future__ import annotations

import argparse
import json
import sys

from linkevo.orchestrator.commands import options


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `walkmodel` subcommand group (fit, predict)."""
    parser = subparsers.add_parser(
        "walkmodel",
        help="learn how far legs walk from the walk maps, and predict whole repertoires",
        description=(
            "A model that predicts, per floor, how far a leg's robot walks in 10 s and "
            "whether it breaks, from what is known without physics (the leg's LEGO build, its "
            "foot path, its 2-D checks, a quasi-static tripod gait): docs/walking.md."
        ),
    )
    sub = parser.add_subparsers(dest="walkmodel_command", required=True, metavar="ACTION")
    fit = sub.add_parser(
        "fit",
        help="fit a walk model on the walk maps of repertoires, measured on held-out ones",
        description=(
            "Fits the walk model on every walked cell of the repertoires REF names (trial run "
            "ids or grid ids; a grid's trials without a walk map are passed over), holding "
            "out whole repertoires to measure it, and logs it as an MLflow run of kind "
            "walk_model: walk_model.pt (weights), walk_model.json (features, sources, "
            "figures), walk_model.png (held-out predictions against walks)."
        ),
    )
    fit.add_argument(
        "refs", nargs="+", metavar="REF", help="a repertoire trial's RUN_ID or a GRID_ID"
    )
    fit.add_argument(
        "--holdout",
        type=holdout_share,
        default=0.2,
        help="share of the repertoires held out to measure the model, at least one; 0 "
        "learns from all, unmeasured",
    )
    options.seed(fit, "seeds the hold-out and the fit")
    fit.add_argument("--json", action="store_true", help="print the figures as JSON")
    options.store(fit)
    fit.set_defaults(func=fit_handler)
    predict = sub.add_parser(
        "predict",
        help="predict every filled cell of repertoires and log walkpred.parquet",
        description=(
            "Predicts, with a walk model, the walk of every filled cell of REF's repertoire "
            "(a trial's RUN_ID, or each repertoire trial of a GRID_ID) and logs "
            "walkpred.parquet to the trial's run; `linkevo explore` then colours cells "
            "without a walk by the predicted distance, marked as predicted."
        ),
    )
    predict.add_argument("ref", help="a repertoire trial's RUN_ID or a GRID_ID")
    predict.add_argument(
        "--model", default=None, help="the walk model's run id (default: the latest fitted)"
    )
    options.store(predict)
    predict.set_defaults(func=predict_handler)


def holdout_share(text: str) -> float:
    """Returns a hold-out share, a number in [0, 1).

    Raises:
        argparse.ArgumentTypeError: naming the value and what is allowed.
    """
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"{text!r} is not allowed: a share in [0, 1)")
    return value


def fit_handler(args: argparse.Namespace) -> int:
    """Handles `linkevo walkmodel fit`."""
    from linkevo.orchestrator.walk_model_runs import describe, fit, log_model, walked_repertoires
    from linkevo.workers.store.runs import RunStore

    store = RunStore.open(args.tracking_uri, args.experiment)
    repertoires = walked_repertoires(store, args.refs)
    print(
        f"learning from {len(repertoires)} repertoire(s), "
        f"{sum(len(r.cells) for r in repertoires)} walked cells",
        file=sys.stderr,
    )
    fitted = fit(repertoires, args.holdout, args.seed)
    run_id = log_model(store, fitted, args.refs, args.seed)
    document = {"run_id": run_id, **describe(fitted)}
    if args.json:
        print(json.dumps(document, indent=2, allow_nan=False))
        return 0
    print(f"walk model: run {run_id}; learned from {fitted.walks} walks")
    if fitted.figures:
        f = fitted.figures
        print(
            f"  held out {', '.join(document['held_out'])}: Spearman flat "
            f"{f['spearman_flat']:.3f}, carpet {f['spearman_carpet']:.3f} (cells that walk); "
            f"break ROC AUC {f['break_auc']:.3f}"
        )
    print(
        f"  predict a repertoire with: {options.linkevo_command('walkmodel', 'predict', 'RUN_ID')}"
    )
    return 0


def predict_handler(args: argparse.Namespace) -> int:
    """Handles `linkevo walkmodel predict`."""
    from linkevo.orchestrator.walk_model_runs import predict
    from linkevo.workers.store.runs import RunStore
    from linkevo.workers.store.walk_models import load_model

    store = RunStore.open(args.tracking_uri, args.experiment)
    trials = store.repertoires(args.ref).trials
    model, model_run = load_model(store, args.model)
    for trial in trials:
        frame = predict(store, trial, model, model_run)
        cells = frame["cell"].nunique()
        lines = [
            f"{trial.trial_key} (run {trial.run_id}): walkpred.parquet, {cells} cells "
            f"predicted by walk model {model_run}"
        ]
        for floor, part in frame.groupby("floor", sort=False):
            sound = part[part["p_break"] < 0.5]
            furthest = "none"
            if len(sound):
                best = sound.sort_values("predicted_cm", ascending=False).iloc[0]
                furthest = f"cell {int(best['cell'])}, {best['predicted_cm']:.1f} cm"
            lines.append(
                f"  {floor}: {len(sound)} predicted not to break; furthest of them "
                f"(predicted): {furthest}"
            )
        print("\n".join(lines))
    return 0
