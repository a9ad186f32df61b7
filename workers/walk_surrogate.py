"""Provides `WalkSurrogate`: a walking trial's pre-screen (`surrogate = true`): the learned
walk model (`algorithms.walk_model`), fitted on the trial's own walks as it goes, decides
which candidates are worth a physics walk.

A candidate that passes the 2-D checks is walked only when the model's optimistic guess
(an upper confidence bound: the ensemble's mean plus `KAPPA` spreads, on the worse floor)
could both walk forwards (the walking QD-score counts only forward walks, offset 0) and
get below the optimizer's bar (`algorithms.Optimizer.bar`: the loss its cell's elite, or
the common grid's, holds; inf for an empty cell), and when the robot is not
likely to break on a floor (`P_BREAK_SKIP`). The others are told with an infinite loss:
they enter no archive, count as `walks_skipped` and cost no walk.

The model is fitted at fixed points of the trial, so a trial is repeatable and resumes as
it ran: first once `START` walks are logged (every candidate is walked until then), then
every `REFIT_EVERY` walks more, each time on the whole walk log so far, seeded by the
fit's number. The log's length at the last fit is the surrogate's checkpointed state: a
resumed trial refits on that many rows and gets the same model.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from linkevo.algorithms.scoring import QD_OFFSETS
from linkevo.algorithms.walk_model import WalkData, WalkModel
from linkevo.sim.robot.walk_features import FEATURE_NAMES, walk_features, walk_targets
from linkevo.sim.robot.walk_rows import COLUMNS, Stage
from linkevo.sim.study import WALKING_FITNESS

START = 200
"""Walks logged before the model first screens."""
REFIT_EVERY = 200
"""Walks between two fits."""
KAPPA = 0.5
"""Spreads added to the predicted distance: the optimism of the upper confidence bound."""
P_BREAK_SKIP = 0.7
"""A candidate whose robot the model gives at least this probability of breaking on either
floor is not walked (a robot that breaks adds nothing to the walking QD-score). With
`KAPPA`, chosen on the first four MAP-LIS F_w trials' walk logs, each screened by a model
of the other three's first 400 walks: 0.56-0.81 of the candidates walked, keeping 0.88-0.97
of the forward distance their walkers add (docs/walking.md)."""


class WalkSurrogate:
    """The pre-screen of one walking trial.

    Args:
        mode: "paper" or "legacy" (the features' decoding).
    """

    def __init__(self, mode: str) -> None:
        self.mode = mode
        self.model: WalkModel | None = None
        self.fitted_rows = 0
        self.fits = 0

    def refresh(self, log) -> None:
        """Fits the model on the walk log (`workers.walk_log.WalkLog`) when it has
        reached the next fixed point (`START`, then every `REFIT_EVERY` walks)."""
        walks = log.counts["walks"]
        due = 0 if walks < START else 1 + (walks - START) // REFIT_EVERY
        if due > self.fits:
            self._fit(log, len(log), due)

    def _fit(self, log, rows: int, fits: int) -> None:
        data = training_data(log, rows, self.mode)
        self.model = WalkModel(len(FEATURE_NAMES)).fit(data, seed=fits) if len(data) else None
        self.fitted_rows, self.fits = rows, fits

    def worth_walking(self, features: Callable[[], np.ndarray], bars: np.ndarray) -> np.ndarray:
        """Returns (N,) which of N candidates, with the optimizer's bars (N,), to walk: all
        of them before the first fit.

        Args:
            features: gives the candidates' (N, F) `sim.robot.walk_features`, asked for
                only once a model is fitted.
        """
        if self.model is None or not len(bars):
            return np.ones(len(bars), dtype=bool)
        prediction = self.model.predict(features())
        optimistic = prediction.distance + KAPPA * prediction.spread  # (N, 2) cm per 10 s
        loss = -optimistic.min(axis=1)  # the walking fitness: the worse floor
        certain_break = (prediction.p_break >= P_BREAK_SKIP).any(axis=1)
        return (loss < np.minimum(bars, QD_OFFSETS[WALKING_FITNESS])) & ~certain_break

    def state_dict(self) -> dict[str, np.ndarray]:
        """Returns what a resumed trial needs to refit the same model."""
        return {"surrogate.rows": np.array(self.fitted_rows), "surrogate.fits": np.array(self.fits)}

    def load_state_dict(self, state: Mapping[str, np.ndarray], log) -> None:
        """Refits the model `state_dict` had, on the first rows of the restored `log`."""
        fits = int(state["surrogate.fits"])
        self.model, self.fitted_rows, self.fits = None, 0, 0
        if fits:
            self._fit(log, int(state["surrogate.rows"]), fits)


def training_data(log, rows: int, mode: str) -> WalkData:
    """Returns the walks of the first `rows` candidates of a walk log that were walked, as
    the walk model learns them (`sim.robot.walk_features.walk_targets`)."""
    import pandas as pd

    walked = np.flatnonzero(log.stage[:rows] == Stage.WALKED)
    frame = pd.DataFrame(
        [{**row, "cell": j} for j, i in enumerate(walked) for row in log.rows(i).values()],
        columns=list(COLUMNS),
    )
    distance, breaks = walk_targets(frame, np.arange(len(walked)))
    return WalkData(walk_features(log.genome[walked], mode), distance, breaks)
