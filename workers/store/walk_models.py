"""Provides `load_model`: a walk model that `linkevo walkmodel fit` logged, read back from
the store and checked against this linkevo's features (`linkevo walkmodel predict` and a
SAIL trial's head start read it)."""

from __future__ import annotations

import tempfile
from pathlib import Path

from linkevo.algorithms.walk_model import WalkModel
from linkevo.sim.errors import LinkevoError
from linkevo.sim.robot.walk_features import FEATURE_NAMES, FEATURES_VERSION
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.runs import NotFound, RunStore


class WalkModelError(LinkevoError, ValueError):
    """A walk model that cannot be fitted or used as asked; the message says what would do."""


def load_model(store: RunStore, run_id: str | None = None) -> tuple[WalkModel, str]:
    """Returns a logged walk model and its run id: run `run_id`'s, else the latest.

    Raises:
        NotFound: no such walk-model run (or none at all).
        WalkModelError: its features are not this linkevo's, or its weights are damaged.
    """
    import torch

    if run_id is None:
        runs = store.search(
            layout.where(layout.WALK_MODEL, "FINISHED"),
            order_by=["attributes.start_time DESC"],
            limit=1,
        )
        if not runs:
            raise NotFound(
                f"no walk model in experiment {store.experiment!r}; fit one with: "
                "linkevo walkmodel fit RUN_ID|GRID_ID"
            )
        run_id = runs[0].info.run_id
    else:
        try:
            tags = store.tags(run_id)
        except NotFound as exc:
            raise NotFound(f"walk model {run_id!r}: no such run in the store {store.uri}") from exc
        if tags.get(layout.KIND) != layout.WALK_MODEL:
            raise NotFound(f"run {run_id} is not a walk model (linkevo walkmodel fit makes one)")
    features = store.tags(run_id).get(layout.FEATURES)
    if features != FEATURES_VERSION:
        raise WalkModelError(
            f"walk model {run_id} was fitted on features {features!r}, this linkevo computes "
            f"{FEATURES_VERSION!r}: fit a new one"
        )
    with tempfile.TemporaryDirectory(prefix="linkevo-walkmodel-") as tmp:
        path = store.download(run_id, layout.WALK_MODEL_PT, Path(tmp))
        try:
            state = torch.load(path, weights_only=True)
            model = WalkModel.from_state_dict(state)
        except Exception as exc:  # torch.load's errors have no common base: a damaged file
            raise WalkModelError(
                f"walk model {run_id}'s weights ({layout.WALK_MODEL_PT}) are damaged "
                f"({type(exc).__name__}: {str(exc)[:200]}); fit a new one with: "
                "linkevo walkmodel fit RUN_ID|GRID_ID"
            ) from exc
    if model.n_features != len(FEATURE_NAMES):
        raise WalkModelError(
            f"walk model {run_id} takes {model.n_features} features, not "
            f"{len(FEATURE_NAMES)}: fit a new one"
        )
    return model, run_id
