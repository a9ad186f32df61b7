"""Provides `Sail`: a walking MAP-Elites trial run as SAIL (`surrogate = "sail"`; Gaier,
Asteroth and Mouret, "Data-Efficient Design Exploration through Surrogate-Assisted
Illumination", 2018): the search runs in the learned walk model, and physics walks go only
to what it proposes.

Each round (every trial iteration after the first, once the model exists):

1. the walk model (`algorithms.walk_model`) is fitted on every walk the trial has made;
2. MAP-Elites runs in the model for `GENERATIONS` generations of `CHILDREN` children, on the
   trial's own descriptor grid, started from the walked map's elites: the **acquisition
   map**. A child's acquisition is optimistic: per floor the predicted distance plus
   `KAPPA` spreads, the worse floor's, times the probability that the robot breaks on
   neither floor (a robot that breaks adds nothing to the walking QD-score). A child that
   fails the 2-D checks is kept only where a cell holds nothing better, and never walked;
3. a batch of at most `PROPOSALS` acquisition elites (and no more than the walks left) is
   walked. An elite qualifies when it is predicted to walk forwards, was not walked
   before in the trial, its acquisition beats what its cell of the walked map holds (a
   walk that cannot enter the walked map is not worth its cost) and the model gives its
   robot under `P_BREAK_SKIP` probability of breaking on each floor. Of these, the
   `SHORTLIST` x batch with the largest gain (the acquisition less what the walked map's
   cell already scores) are spread over the map as SAIL spreads its samples: each point of
   a scrambled Sobol sequence over the descriptor space takes the nearest one not yet
   taken.

The walked candidates enter the **walked map** (the trial's repertoire: the walking
QD-score, the best walker and every reader of a repertoire see real walks only). Until
the model exists (`START` walks without a head start) the trial's own MAP-Elites varies
the walked map, as a plain trial does; with a head start (`walk_model`, a model fitted by
`linkevo walkmodel fit`) the model proposes from the second batch on, and is fine-tuned
on the trial's walks once it has `START` of them.

At the end the model, fitted on every walk, illuminates the **prediction map** with its
mean (no optimism): a cell per illuminated cell with its genome, the predicted distance
and spread per floor and the break probability (`prediction_map.parquet`, read by the
explorer and `linkevo pull RUN_ID:CELL`).

Every fit and every illumination is seeded by the number of walk-log rows it read, so a
trial is repeatable, and a resumed trial, whose walk log is restored from its checkpoint,
proposes what the uninterrupted one did: the rounds keep no state of their own.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
from scipy.stats import qmc

from linkevo.algorithms.individuals import Individuals
from linkevo.algorithms.map_elites import MapElites
from linkevo.algorithms.walk_model import Prediction, WalkModel
from linkevo.sim.linkage.evaluating import evaluate_with_motion
from linkevo.sim.linkage.evaluation import Evaluation
from linkevo.sim.linkage.physical import physical_checks
from linkevo.sim.robot.walk_features import FEATURE_NAMES, features_of_rows
from linkevo.sim.robot.walk_fitness import REJECTED_LOSS
from linkevo.sim.robot.walk_rows import FLOOR_ORDER
from linkevo.sim.study import DEFAULT_WALK_BATCH, WALKING_FITNESS
from linkevo.workers.walk_log import WalkLog
from linkevo.workers.walk_surrogate import P_BREAK_SKIP, training_data

START = 64
"""Walks the trial makes before it fits its first model (without a head start)."""
KAPPA = 0.5
"""Spreads added to each floor's predicted distance in the acquisition (the screen's)."""
GENERATIONS = 60
"""MAP-Elites generations in the model per round..."""
CHILDREN = 128
"""...each of this many children."""
PROPOSALS = DEFAULT_WALK_BATCH
"""Acquisition elites walked per round (at most)."""
SHORTLIST = 4
"""The batch is spread over this many times its size of the qualifying elites with the
largest gain."""


def acquisition(prediction: Prediction, kappa: float) -> np.ndarray:
    """Returns (N,) the value of N predicted legs: per floor the distance plus `kappa`
    spreads (cm per 10 s), the worse floor's, times the probability of breaking on
    neither floor."""
    optimistic = (prediction.distance + kappa * prediction.spread).min(axis=1)
    sound = np.prod(1.0 - prediction.p_break, axis=1)
    return np.where(optimistic > 0, optimistic * sound, optimistic)


@dataclasses.dataclass(frozen=True)
class Illumination:
    """An illuminated map: its elites (K rows, `Individuals`, loss = minus the value),
    their cells (K,) and bins (K, D), and the model's prediction for each."""

    elites: Individuals
    cells: np.ndarray
    bins: np.ndarray
    prediction: Prediction


def illuminate(
    model: WalkModel,
    starts: np.ndarray,
    *,
    approach: str,
    mode: str,
    n_angles: int,
    seed: int,
    kappa: float,
) -> Illumination | None:
    """Runs MAP-Elites in the model from `starts` (K, 56) (random genomes when K = 0);
    returns the map's buildable elites, or None when it holds none."""
    search = MapElites(
        approach=approach,
        fitness=WALKING_FITNESS,
        batch_size=CHILDREN,
        mode=mode,
        seed=seed,
        n_angles=n_angles,
    )
    if len(starts):
        search.seed_with(starts)

    def predicted(genomes: np.ndarray) -> Evaluation:
        base, batch, motion = evaluate_with_motion(genomes, "Fp", mode, n_angles=n_angles)
        buildable = np.flatnonzero(physical_checks(batch, motion).buildable)
        loss = np.full(len(genomes), REJECTED_LOSS)
        if len(buildable):
            guess = model.predict(features_of_rows(batch, motion, buildable))
            loss[buildable] = -acquisition(guess, kappa)
        return dataclasses.replace(base, loss=loss)

    for _ in range(GENERATIONS + 1):
        genomes = search.ask()
        search.tell(genomes, predicted(genomes))
    elites = search.archive.elites
    assert elites is not None
    keep = np.flatnonzero(elites.loss < REJECTED_LOSS)
    if not len(keep):
        return None
    elites = elites.take(keep)
    _, batch, motion = evaluate_with_motion(elites.genome, "Fp", mode, n_angles=n_angles)
    prediction = model.predict(features_of_rows(batch, motion, np.arange(len(keep))))
    cells = search.archive.cells[keep]
    return Illumination(elites, cells, search.archive.bins(elites.desc), prediction)


def spread_pick(bins: np.ndarray, resolution: int, n: int, seed: int) -> np.ndarray:
    """Returns the indices of n of the rows of `bins` (M, D) spread over the grid: each
    point of a scrambled Sobol sequence takes the nearest row not yet taken."""
    if n >= len(bins):
        return np.arange(len(bins))
    sobol = qmc.Sobol(bins.shape[1], seed=seed)
    points = sobol.random_base2(int(np.ceil(np.log2(n))))[:n] * resolution
    centres = bins + 0.5
    free = np.ones(len(bins), dtype=bool)
    picked = []
    for point in points:
        distance = np.where(free, ((centres - point) ** 2).sum(axis=1), np.inf)
        i = int(np.argmin(distance))
        free[i] = False
        picked.append(i)
    return np.array(picked, dtype=np.int64)


class Sail:
    """The SAIL rounds of one walking trial.

    Args:
        approach: the trial's MAP-Elites approach (one of `sim.study.SAIL_APPROACHES`,
            as `TrialSpec` checks).
        mode: "paper" or "legacy".
        n_angles: the trial's crank angles.
        seed: the trial's seed.
        walks: the trial's budget of walks.
        head_start: a fitted walk model to start from, on this linkevo's features
            (`workers.store.walk_models.load_model` checks); None: learn from the trial alone.
    """

    def __init__(
        self,
        approach: str,
        mode: str,
        n_angles: int,
        seed: int,
        walks: int,
        head_start: WalkModel | None = None,
    ) -> None:
        self.approach = approach
        self.mode = mode
        self.n_angles = n_angles
        self.seed = seed
        self.walks = walks
        self.head_start = head_start
        self._fitted: tuple[int, WalkModel | None] = (-1, None)

    def model(self, log: WalkLog) -> WalkModel | None:
        """Returns the model of the walk log as it stands: fitted on all its walks (the
        head start fine-tuned on them), the head start alone before `START` walks, or
        None without one. A log of the same length gives the same model."""
        rows = len(log)
        if self._fitted[0] != rows:
            model = self.head_start
            if log.counts["walks"] >= START:
                data = training_data(log, rows, self.mode)
                if self.head_start is None:
                    model = WalkModel(len(FEATURE_NAMES)).fit(data, seed=rows)
                else:
                    warm = WalkModel.from_state_dict(self.head_start.state_dict())
                    model = warm.fit(data, seed=rows, warm=True)
            self._fitted = (rows, model)
        return self._fitted[1]

    def proposer(self, log: Callable[[], WalkLog], walked_map: MapElites):
        """Returns the walked map's proposer (`algorithms.optimizer.Proposer`): each call
        runs a round on the walk log `log()` gives, or returns None (the walked map's own
        variation) while there is no model or nothing worth walking."""

        def propose() -> tuple[np.ndarray, np.ndarray] | None:
            walk_log = log()
            left = self.walks - walk_log.counts["walks"]
            model = self.model(walk_log)
            if model is None or left <= 0:
                return None
            found = self._illuminate(model, walked_map, len(walk_log), KAPPA)
            if found is None:
                return None
            walked = {g.tobytes() for g in walk_log.genome}
            value = -found.elites.loss
            held = walked_map.archive.incumbents(found.elites.desc)
            fresh = np.array([g.tobytes() not in walked for g in found.elites.genome], bool)
            sound = (found.prediction.p_break < P_BREAK_SKIP).all(axis=1)
            worth = np.flatnonzero((value > 0) & fresh & (found.elites.loss < held) & sound)
            if not len(worth):
                return None
            n = min(PROPOSALS, left)
            gain = value[worth] - np.maximum(-held[worth], 0.0)
            worth = worth[np.argsort(-gain, kind="stable")[: SHORTLIST * n]]
            resolution = walked_map.archive.space.resolution
            picked = worth[spread_pick(found.bins[worth], resolution, n, len(walk_log))]
            return found.elites.genome[picked], found.elites.sigma[picked]

        return propose

    def prediction_map(self, log: WalkLog, walked_map: MapElites) -> dict[str, np.ndarray]:
        """Returns the prediction map as columns (a row per illuminated cell): cell, loss
        (minus the predicted worse-floor distance times the chance of no break), error,
        desc_d, bin_d, genome (K, 56), per floor `<floor>_predicted_cm`,
        `<floor>_spread_cm` and `<floor>_p_break`, and `walked` (the cell is in the
        walked map); empty columns when there is no model."""
        model = self.model(log)
        found = None if model is None else self._illuminate(model, walked_map, -1, 0.0)
        if found is None:
            return {}
        elites, p = found.elites, found.prediction
        columns = {
            "cell": found.cells.astype(np.int64),
            "loss": elites.loss.astype(np.float64),
            "error": elites.error.astype(np.int64),
        }
        columns |= {f"desc_{d}": elites.desc[:, d] for d in range(elites.desc.shape[1])}
        columns |= {
            f"bin_{d}": found.bins[:, d].astype(np.int64) for d in range(found.bins.shape[1])
        }
        columns["genome"] = elites.genome
        for k, floor in enumerate(FLOOR_ORDER):
            columns[f"{floor}_predicted_cm"] = p.distance[:, k]
            columns[f"{floor}_spread_cm"] = p.spread[:, k]
            columns[f"{floor}_p_break"] = p.p_break[:, k]
        columns["walked"] = np.isin(found.cells, walked_map.archive.cells)
        return columns

    def _illuminate(
        self, model: WalkModel, walked_map: MapElites, rows: int, kappa: float
    ) -> Illumination | None:
        elites = walked_map.archive.elites
        starts = np.zeros((0, 56)) if elites is None else elites.genome
        return illuminate(
            model,
            starts,
            approach=self.approach,
            mode=self.mode,
            n_angles=self.n_angles,
            seed=self.seed * 1_000_003 + rows + 1,
            kappa=kappa,
        )
