"""Provides AuroraMapElites: MAP-Elites in a 4-D space learned by a path autoencoder (MAP-AU)."""

from __future__ import annotations

import time
from dataclasses import asdict

import numpy as np
import torch

from linkevo.algorithms.aurora_model import PathAutoencoder
from linkevo.algorithms.aurora_paths import prepare_paths, valid_rows
from linkevo.algorithms.aurora_settings import AuroraSettings
from linkevo.algorithms.individuals import Individuals
from linkevo.algorithms.map_elites import MapElites
from linkevo.sim.linkage.evaluation import Evaluation
from linkevo.sim.study import DEFAULT_ANGLES

_TORCH_SEED_TAG = 0xA0A0
"""Mixed into the trial seed so the encoder's random streams differ from the search's."""


class AuroraMapElites(MapElites):
    """MAP-Elites whose four descriptors are the bottleneck of an autoencoder of foot paths.

    The first batch (the random initial population) trains the encoder on its valid paths
    (`initial_epochs`) before it is placed. After every `retrain_period`-th iteration the
    encoder trains `retrain_epochs` more on the valid paths of the repertoire and every
    elite (invalid ones too, as published) is re-placed with the new encoder into the
    10^4 grid; elites that collide keep the lowest loss, and the number dropped is
    reported. Only paths with error == 0 ever reach training.

    `metrics()` adds `recon_loss` (mean absolute reconstruction error over the training
    set just after a training; NaN in iterations without one), `train_paths` (paths
    trained on, 0 without training) and `elites_dropped` (at the re-indexing; NaN
    without one).

    Args:
        fitness, batch_size, mode, seed, n_angles, initial_sigma: as `BaseOptimizer`.
        **options: `AuroraSettings` fields.
    """

    def __init__(
        self,
        *,
        fitness: str,
        batch_size: int,
        mode: str,
        seed: int,
        n_angles: int = DEFAULT_ANGLES,
        initial_sigma: float | None = None,
        **options: object,
    ) -> None:
        self.aurora = AuroraSettings.from_options(options)
        super().__init__(
            approach="MAP-AU",
            fitness=fitness,
            batch_size=batch_size,
            mode=mode,
            seed=seed,
            n_angles=n_angles,
            initial_sigma=initial_sigma,
        )
        self._encoder = PathAutoencoder(
            n_inputs=2 * self.n_angles,
            seed=self.training_seed(-1),
            device=self.aurora.resolved_device(),
            threads=self.aurora.threads,
        )
        self._trainings = 0
        self._last: dict[str, float] = self._no_training()
        self.training_seconds = 0.0
        """Wall-clock seconds spent training and re-indexing (not part of the state)."""

    @property
    def encoder(self) -> PathAutoencoder:
        """The path autoencoder."""
        return self._encoder

    def training_seed(self, index: int) -> int:
        """Returns the torch seed of training session `index` (0 = initial; -1 = weights).

        Derived from the trial seed alone, so a resumed trial shuffles identically.
        """
        return int(
            np.random.SeedSequence([self.seed, _TORCH_SEED_TAG, index + 1]).generate_state(1)[0]
        )

    @property
    def trainings(self) -> int:
        """Training sessions so far (the initial one included)."""
        return self._trainings

    def paths_of(self, foot_x: np.ndarray, foot_y: np.ndarray) -> np.ndarray:
        """Returns the network input of foot paths (N, A) x2, shape (N, 2A) float32."""
        return prepare_paths(
            foot_x, foot_y, self.aurora.representation, scale=self.aurora.path_scale
        )

    def encode(self, foot_x: np.ndarray, foot_y: np.ndarray) -> np.ndarray:
        """Returns the learned descriptors of foot paths (N, A) x2, shape (N, 4) in [0, 1]."""
        return self._encoder.encode(self.paths_of(foot_x, foot_y))

    def descriptors_of(self, genomes: np.ndarray, evaluation: Evaluation) -> np.ndarray:
        """Returns the encodings (B, 4) of the batch's foot paths.

        On the first batch the encoder first takes its initial training on the batch's
        valid paths, so the initial population is placed by a trained encoder.
        """
        if self._iteration == 0:
            started = time.perf_counter()
            self._train(evaluation.foot_x, evaluation.foot_y, evaluation.error, initial=True)
            self.training_seconds += time.perf_counter() - started
        return self.encode(evaluation.foot_x, evaluation.foot_y)

    def bar(self, genomes: np.ndarray, evaluation: Evaluation) -> np.ndarray:
        """Returns MapElites' bar, inf before the first batch (whose encoding would train
        the encoder; the archive is empty then anyway)."""
        if self._iteration == 0:
            return np.full(len(genomes), np.inf)
        return super().bar(genomes, evaluation)

    def _survive(self, batch: Individuals, *, initial: bool) -> None:
        if not initial:
            self._last = self._no_training()
        super()._survive(batch, initial=initial)
        if initial or self._iteration % self.aurora.retrain_period != 0:
            return
        elites = self._archive.elites
        if elites is None:
            return
        started = time.perf_counter()
        self._train(elites.foot_x, elites.foot_y, elites.error, initial=False)
        self._last["elites_dropped"] = float(
            self.reindex(self.encode(elites.foot_x, elites.foot_y))
        )
        self.training_seconds += time.perf_counter() - started

    def _train(
        self, foot_x: np.ndarray, foot_y: np.ndarray, error: np.ndarray, *, initial: bool
    ) -> None:
        """Trains the encoder on the valid rows (paths with error == 0), if there are any."""
        rows = valid_rows(error)
        if rows.size == 0:
            return
        epochs = self.aurora.initial_epochs if initial else self.aurora.retrain_epochs
        result = self._encoder.train(
            self.paths_of(foot_x[rows], foot_y[rows]),
            epochs=epochs,
            batch_size=self.aurora.ae_batch_size,
            learning_rate=self.aurora.learning_rate,
            seed=self.training_seed(self._trainings),
        )
        self._trainings += 1
        self._last["recon_loss"] = result.final_loss
        self._last["train_paths"] = float(result.n_samples)

    @staticmethod
    def _no_training() -> dict[str, float]:
        return {"recon_loss": float("nan"), "train_paths": 0.0, "elites_dropped": float("nan")}

    def _summary(self) -> dict[str, float]:
        return super()._summary() | self._last

    def settings(self) -> dict[str, object]:
        """Returns the JSON-able settings, the autoencoder's included."""
        return super().settings() | {"aurora": asdict(self.aurora)}

    def torch_state(self) -> dict[str, torch.Tensor]:
        """Returns the encoder's state dict (weights and Adagrad sums, CPU tensors).

        The trial loop saves it with `torch.save`; it loads back with
        `torch.load(path, weights_only=True)` and `load_torch_state`.
        """
        return self._encoder.state_dict()

    def load_torch_state(self, state: dict[str, torch.Tensor]) -> None:
        """Loads an encoder state dict given by `torch_state`."""
        self._encoder.load_state_dict(state)

    def _state(self) -> dict[str, np.ndarray]:
        encoder = {
            f"aurora.encoder.{name}": tensor.numpy() for name, tensor in self.torch_state().items()
        }
        return (
            super()._state()
            | encoder
            | {
                "aurora.trainings": np.array(self._trainings, dtype=np.int64),
                "aurora.last": np.array(
                    [self._last[k] for k in ("recon_loss", "train_paths", "elites_dropped")]
                ),
            }
        )

    def _load_state(self, state: dict[str, np.ndarray]) -> None:
        super()._load_state(state)
        prefix = "aurora.encoder."
        self.load_torch_state(
            {
                key.removeprefix(prefix): torch.from_numpy(np.array(value))
                for key, value in state.items()
                if key.startswith(prefix)
            }
        )
        self._trainings = int(state["aurora.trainings"])
        recon, paths, dropped = (float(v) for v in np.asarray(state["aurora.last"]))
        self._last = {"recon_loss": recon, "train_paths": paths, "elites_dropped": dropped}
