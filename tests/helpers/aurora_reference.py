"""Provides the plain torch.nn + autograd + torch.optim version of the AURORA training loop.

It is the oracle the fused `PathAutoencoder` loop is checked against and the baseline its
speed is measured against; the search never uses it.
"""

from __future__ import annotations

import itertools

import numpy as np
import torch

from linkevo.algorithms.aurora_model import (
    BOTTLENECK,
    EPSILON,
    INITIAL_ACCUMULATOR,
    N_LAYERS,
    layer_sizes,
    torch_threads,
)


def module_index(layer: int) -> int:
    """Returns where Linear `layer` (0..9) sits in `reference_module` (the sigmoid is a module)."""
    return layer if layer < BOTTLENECK else layer + 1


def reference_module(state: dict[str, torch.Tensor]) -> torch.nn.Sequential:
    """Returns the autoencoder as a plain `torch.nn.Sequential` holding `state`'s weights.

    Args:
        state: a `PathAutoencoder.state_dict()` (`"layers.<i>.weight"` / `.bias`).
    """
    n_inputs = int(state["layers.0.weight"].shape[1])
    modules: list[torch.nn.Module] = []
    for layer, (fan_in, fan_out) in enumerate(itertools.pairwise(layer_sizes(n_inputs))):
        modules.append(torch.nn.Linear(fan_in, fan_out))
        if layer == BOTTLENECK - 1:
            modules.append(torch.nn.Sigmoid())
    module = torch.nn.Sequential(*modules)
    with torch.no_grad():
        for layer in range(N_LAYERS):
            linear = module[module_index(layer)]
            linear.weight.copy_(state[f"layers.{layer}.weight"])
            linear.bias.copy_(state[f"layers.{layer}.bias"])
    return module


def train_reference(
    module: torch.nn.Sequential,
    x: np.ndarray,
    *,
    epochs: int,
    batch_size: int,
    learning_rate: float,
    seed: int,
    threads: int = 1,
) -> None:
    """Trains `module` on `x` (N, 80) in place, visiting batches as `PathAutoencoder.train`.

    Uses `torch.optim.Adagrad` with Keras's initial accumulator and epsilon and
    `torch.nn.L1Loss` (mean absolute error) through autograd, on `threads` CPU threads.
    """
    data = torch.as_tensor(x, dtype=torch.float32)
    optimiser = torch.optim.Adagrad(
        module.parameters(),
        lr=learning_rate,
        initial_accumulator_value=INITIAL_ACCUMULATOR,
        eps=EPSILON,
    )
    criterion = torch.nn.L1Loss()
    generator = torch.Generator().manual_seed(int(seed))
    with torch_threads(threads):
        for _ in range(epochs):
            order = torch.randperm(data.shape[0], generator=generator)
            for start in range(0, data.shape[0], batch_size):
                batch = data[order[start : start + batch_size]]
                optimiser.zero_grad(set_to_none=True)
                criterion(module(batch), batch).backward()
                optimiser.step()
