"""Provides the learned walk model: per floor, the distance a leg walks in 10 s and whether
its robot breaks, predicted from `sim.robot.walk_features` (no physics), with a spread.

The model is an ensemble of `MEMBERS` small multilayer perceptrons (torch), each trained
from its own seed on its own bootstrap sample of the walks; the ensemble's mean is the
prediction and its standard deviation the spread (what a search's acquisition reads,
`workers.walk_evaluator`). Each member has four outputs: the distance on each floor of
`FLOOR_ORDER` (standardised, fitted with a Huber loss on the walks that do not break there) and
the log-odds that the robot breaks there (binary cross-entropy on every walk on that
floor). Distances are cm per the study's 10 s. Inputs are standardised by the training
set's mean and spread, kept in the state dict with the weights: `state_dict` is plain
tensors, so `torch.load(path, weights_only=True)` reads a saved model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from linkevo.algorithms.aurora_model import torch_threads
from linkevo.sim.robot.walk_rows import FLOOR_ORDER

MEMBERS = 5
"""Networks in the ensemble."""
HIDDEN: tuple[int, ...] = (128, 64)
"""Units of each member's hidden layers."""
EPOCHS = 40
"""Passes over the data per member, in batches of `BATCH`..."""
STEPS = (300, 3000)
"""...within these optimiser steps per member (few walks still get a fit; many, a bound)."""
BATCH = 256
LEARNING_RATE = 2e-3
WEIGHT_DECAY = 1e-4


@dataclass(frozen=True)
class WalkData:
    """Walks to learn from: features (N, F) float32; distance (N, 2) cm per 10 s on each
    of `FLOOR_ORDER`, NaN where the leg was not walked there or broke; breaks (N, 2) 1.0 broke,
    0.0 walked soundly, NaN not walked there."""

    features: np.ndarray
    distance: np.ndarray
    breaks: np.ndarray

    def __len__(self) -> int:
        return len(self.features)


@dataclass(frozen=True)
class Prediction:
    """The ensemble's prediction for N legs: distance (N, 2) cm per 10 s and its spread
    (N, 2) (the members' standard deviation), and p_break (N, 2), on each of `FLOOR_ORDER`."""

    distance: np.ndarray
    spread: np.ndarray
    p_break: np.ndarray


def _member(n_features: int) -> nn.Sequential:
    layers: list[nn.Module] = []
    width = n_features
    for units in HIDDEN:
        layers += [nn.Linear(width, units), nn.ReLU()]
        width = units
    return nn.Sequential(*layers, nn.Linear(width, 2 * len(FLOOR_ORDER)))


class WalkModel:
    """The ensemble and its standardisation.

    Args:
        n_features: inputs per leg (F).
        members: networks in the ensemble.
    """

    def __init__(self, n_features: int, members: int = MEMBERS) -> None:
        self.n_features = n_features
        self.members = [_member(n_features) for _ in range(members)]
        self.feature_mean = torch.zeros(n_features)
        self.feature_scale = torch.ones(n_features)
        self.distance_mean = torch.zeros(len(FLOOR_ORDER))
        self.distance_scale = torch.ones(len(FLOOR_ORDER))

    def fit(self, data: WalkData, seed: int = 0, warm: bool = False) -> WalkModel:
        """Trains every member on its bootstrap sample of `data`; returns the model.

        Args:
            warm: fine-tune: start from the model's weights and keep its standardisation
                (a fitted model refitted on new walks: a walking trial's head start),
                rather than from fresh weights and `data`'s own standardisation.
        """
        if not len(data):
            raise ValueError("a walk model needs at least one walk to learn from")
        x = torch.from_numpy(np.asarray(data.features, np.float32))
        d = torch.from_numpy(np.asarray(data.distance, np.float32))
        sound = ~torch.isnan(d)
        if not warm:
            self.feature_mean = x.mean(dim=0)
            self.feature_scale = x.std(dim=0).clamp_min(1e-6)
            for k in range(len(FLOOR_ORDER)):
                values = d[sound[:, k], k]
                if len(values) > 1:
                    self.distance_mean[k] = values.mean()
                    self.distance_scale[k] = values.std().clamp_min(1e-3)
        x = (x - self.feature_mean) / self.feature_scale
        d = torch.nan_to_num((d - self.distance_mean) / self.distance_scale)
        b = torch.from_numpy(np.asarray(data.breaks, np.float32))
        seen = ~torch.isnan(b)
        b = torch.nan_to_num(b)
        steps = int(np.clip(EPOCHS * -(-len(x) // BATCH), *STEPS))
        with torch_threads(1):
            for i, member in enumerate(self.members):
                generator = torch.Generator().manual_seed(seed * 1000 + i)
                for layer in member:
                    if isinstance(layer, nn.Linear) and not warm:
                        bound = 1.0 / np.sqrt(layer.in_features)
                        with torch.no_grad():
                            layer.weight.uniform_(-bound, bound, generator=generator)
                            layer.bias.uniform_(-bound, bound, generator=generator)
                sample = torch.randint(len(x), (len(x),), generator=generator)
                _train(
                    member,
                    x[sample],
                    d[sample],
                    sound[sample],
                    b[sample],
                    seen[sample],
                    generator,
                    steps,
                )
        return self

    @torch.no_grad()
    def predict(self, features: np.ndarray) -> Prediction:
        """Returns the prediction for features (N, F)."""
        x = torch.from_numpy(np.asarray(features, np.float32).reshape(-1, self.n_features))
        x = (x - self.feature_mean) / self.feature_scale
        with torch_threads(1):
            out = torch.stack([m(x) for m in self.members])  # (M, N, 4)
        n = len(FLOOR_ORDER)
        distance = out[..., :n] * self.distance_scale + self.distance_mean
        p_break = torch.sigmoid(out[..., n:]).mean(dim=0)
        return Prediction(
            distance=distance.mean(dim=0).numpy().astype(np.float64),
            spread=distance.std(dim=0, unbiased=False).numpy().astype(np.float64),
            p_break=p_break.numpy().astype(np.float64),
        )

    def state_dict(self) -> dict[str, torch.Tensor]:
        """Returns the model as plain tensors (weights and standardisation)."""
        state = {
            "feature_mean": self.feature_mean,
            "feature_scale": self.feature_scale,
            "distance_mean": self.distance_mean,
            "distance_scale": self.distance_scale,
        }
        for i, member in enumerate(self.members):
            state |= {f"member{i}.{k}": v for k, v in member.state_dict().items()}
        return {k: v.detach().clone() for k, v in state.items()}

    @classmethod
    def from_state_dict(cls, state: dict[str, torch.Tensor]) -> WalkModel:
        """Returns the model `state_dict` gave.

        Raises:
            ValueError: it is not one (not a table of tensors, a tensor missing or of
                another shape), or a weight is not a finite number (it would predict NaN).
        """
        if not isinstance(state, dict) or not all(
            isinstance(v, torch.Tensor) for v in state.values()
        ):
            raise ValueError(f"not a walk model's state: a {type(state).__name__}, not tensors")
        bad = sorted(k for k, v in state.items() if not bool(torch.isfinite(v).all()))
        if bad:
            raise ValueError(f"its weights {', '.join(bad[:3])} hold values that are not finite")
        try:
            n_features = int(state["feature_mean"].shape[0])
            members = len({k.split(".")[0] for k in state if k.startswith("member")})
            model = cls(n_features, members)
            for name in ("feature_mean", "feature_scale", "distance_mean", "distance_scale"):
                setattr(model, name, state[name].clone())
            for i, member in enumerate(model.members):
                prefix = f"member{i}."
                member.load_state_dict(
                    {k.removeprefix(prefix): v for k, v in state.items() if k.startswith(prefix)}
                )
        except (KeyError, RuntimeError, IndexError, TypeError) as exc:
            raise ValueError(f"not a walk model's state: {exc}") from exc
        return model


def _train(member: nn.Sequential, x, d, sound, b, seen, generator, steps: int) -> None:
    """Fits one member: Huber on the sound distances, cross-entropy on the breaks."""
    optimiser = torch.optim.Adam(member.parameters(), lr=LEARNING_RATE, weight_decay=WEIGHT_DECAY)
    n = len(FLOOR_ORDER)
    huber = nn.HuberLoss(reduction="none")
    entropy = nn.BCEWithLogitsLoss(reduction="none")
    for _ in range(steps):
        rows = torch.randint(len(x), (min(BATCH, len(x)),), generator=generator)
        out = member(x[rows])
        fit = huber(out[:, :n], d[rows]) * sound[rows]
        broke = entropy(out[:, n:], b[rows]) * seen[rows]
        loss = fit.sum() / sound[rows].sum().clamp_min(1)
        loss = loss + broke.sum() / seen[rows].sum().clamp_min(1)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
