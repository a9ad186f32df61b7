"""Benchmark: the learned walk model held out one repertoire at a time.

Run: `.venv/bin/python benchmarks/walkmodel_holdout.py --tracking-uri URI REF [REF ...]`.

Reads every walked cell of the repertoires REF names (trial run ids or grid ids, as
`linkevo walkmodel fit` does), then, for each repertoire in turn, fits the walk model on
all the others and measures it on that one (`orchestrator.walk_model_runs.figures`: Spearman of
predicted and walked distance among the cells that walk there without breaking, per floor;
the break classifier's ROC AUC over both floors). Prints a row per held-out repertoire and
the median. Goal (issue: the learned walk model): Spearman >= 0.8 per floor, AUC >= 0.9.
"""

from __future__ import annotations

import argparse

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("refs", nargs="+", metavar="REF")
    parser.add_argument("--tracking-uri", required=True)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    from linkevo.algorithms.walk_model import WalkModel
    from linkevo.orchestrator.walk_model_runs import figures, pooled, walked_repertoires
    from linkevo.sim.robot.walk_features import FEATURE_NAMES
    from linkevo.workers.store.runs import RunStore

    repertoires = walked_repertoires(RunStore.open(args.tracking_uri), args.refs)
    rows = []
    for i, held in enumerate(repertoires):
        train = pooled([r for j, r in enumerate(repertoires) if j != i])
        model = WalkModel(len(FEATURE_NAMES)).fit(train, seed=args.seed)
        found = figures(model.predict(held.data.features), held.data)
        rows.append((found["spearman_flat"], found["spearman_carpet"], found["break_auc"]))
        print(
            f"{held.trial.trial_key:16s} {len(held.cells):6d} cells   Spearman flat "
            f"{rows[-1][0]:.3f}  carpet {rows[-1][1]:.3f}   break AUC {rows[-1][2]:.3f}",
            flush=True,
        )
    flat, carpet, auc = np.nanmedian(np.array(rows), axis=0)
    print(
        f"{'median':16s} {'':12s} Spearman flat {flat:.3f}  carpet {carpet:.3f}   "
        f"break AUC {auc:.3f}"
    )


if __name__ == "__main__":
    main()
