"""Provides the AURORA path autoencoder and its fused Adagrad training loop (spec §6)."""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import torch

from linkevo.algorithms.aurora_kernel import encode_batch, epoch_workspace, train_epoch

HIDDEN_SIZES: tuple[int, ...] = (64, 48, 32, 16, 4, 16, 32, 48, 64)
"""Units of the hidden layers; the 4-unit layer is the sigmoid bottleneck."""
BOTTLENECK = 1 + HIDDEN_SIZES.index(4)
"""Index of the bottleneck among the layer sizes (= number of encoder layers)."""
N_LAYERS = len(HIDDEN_SIZES) + 1
"""Linear layers: ten."""
CODE_SIZE = 4
ENCODE_COLUMNS = 256
"""Paths the compiled encoder takes per block."""
INITIAL_ACCUMULATOR = 0.1
"""Adagrad's starting sum of squared gradients (Keras's default, as published)."""
EPSILON = 1e-7
"""Adagrad's denominator guard (Keras's default)."""
LOOPS: tuple[str, ...] = ("auto", "compiled", "torch")
"""Training loops: "compiled" (`aurora_kernel`, CPU only), "torch" (tensor operations, any
device); "auto" takes the compiled loop on the CPU and torch elsewhere."""


def layer_sizes(n_inputs: int) -> tuple[int, ...]:
    """Returns the units per layer, input to output: (n, 64, 48, 32, 16, 4, ..., 64, n)."""
    return (n_inputs, *HIDDEN_SIZES, n_inputs)


@contextlib.contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Sets torch's intra-op CPU threads to `n` inside the block, restoring them after.

    One thread is the default: the matrices are small, and with two OpenMP threads on a
    busy machine every operation waits for a descheduled partner (tens of times slower).
    """
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


@dataclass(frozen=True)
class TrainingResult:
    """What one training session gives back.

    Attributes:
        initial_loss: mean absolute reconstruction error over the training set before
            the first step.
        final_loss: the same after the last step (one forward pass over the whole set).
        n_samples: number of paths trained on.
        n_steps: number of Adagrad steps taken.
    """

    initial_loss: float
    final_loss: float
    n_samples: int
    n_steps: int


class PathAutoencoder:
    """The 80-64-48-32-16-4-16-32-48-64-80 autoencoder, trained by a hand-written loop.

    Hidden layers are linear and the bottleneck is a sigmoid, as in the authors'
    published Keras model; weights start Glorot-uniform and biases at zero (Keras
    defaults). All parameters live in one flat float32 vector; the backward pass is
    written out by hand (no autograd). On the CPU a whole epoch runs in one compiled call
    (`algorithms.aurora_kernel`); on a GPU an Adagrad step is a few tensor operations.
    Both compute the gradients of `torch.nn` + `torch.optim` (tests hold them equal).

    Args:
        n_inputs: input and output width, 2A for A crank angles (80 in the study).
        seed: seeds the weight initialisation.
        device: a torch device string ("cpu", "cuda", ...).
        threads: torch CPU threads while encoding and in the torch loop; results are
            reproducible for a fixed count (the compiled loop is single-threaded).
        loop: one of `LOOPS`.
    """

    def __init__(
        self,
        *,
        n_inputs: int = 80,
        seed: int,
        device: str = "cpu",
        threads: int = 1,
        loop: str = "auto",
    ) -> None:
        if n_inputs < 2 or threads < 1:
            raise ValueError(f"need n_inputs >= 2 and threads >= 1, got {n_inputs} and {threads}")
        if loop not in LOOPS:
            raise ValueError(f"unknown training loop {loop!r}; allowed: {', '.join(LOOPS)}")
        if loop == "compiled" and torch.device(device).type != "cpu":
            raise ValueError(f"the compiled loop runs on the CPU only, got device {device!r}")
        self._threads = threads
        self._device = torch.device(device)
        self._compiled = loop == "compiled" or (loop == "auto" and self._device.type == "cpu")
        self._sizes = layer_sizes(n_inputs)
        self._layout: list[tuple[int, int, int, int]] = []
        offset = 0
        for fan_in, fan_out in itertools.pairwise(self._sizes):
            self._layout.append((offset, offset + fan_in * fan_out, fan_in, fan_out))
            offset += fan_in * fan_out + fan_out
        self._n_parameters = offset
        generator = torch.Generator().manual_seed(int(seed))
        theta = torch.zeros(offset, dtype=torch.float32)
        for w_off, _, fan_in, fan_out in self._layout:
            limit = float(np.sqrt(6.0 / (fan_in + fan_out)))
            theta[w_off : w_off + fan_in * fan_out] = (
                torch.rand(fan_in * fan_out, generator=generator) * 2.0 - 1.0
            ) * limit
        self._bind(theta, torch.full_like(theta, INITIAL_ACCUMULATOR))

    def _bind(self, theta: torch.Tensor, accumulator: torch.Tensor) -> None:
        """Moves the flat vectors to the device and caches each layer's views into them.

        The views stay valid because every update is in place.
        """
        self._theta = theta.to(self._device)
        self._accumulator = accumulator.to(torch.float32).clone().to(self._device)
        self._grad = torch.zeros_like(self._theta)
        self._denominator = torch.zeros_like(self._theta)
        self._weights = [self._weight(self._theta, i) for i in range(N_LAYERS)]
        self._weights_t = [w.t() for w in self._weights]
        self._biases = [self._bias(self._theta, i) for i in range(N_LAYERS)]
        self._grad_weights = [self._weight(self._grad, i) for i in range(N_LAYERS)]
        self._grad_biases = [self._bias(self._grad, i) for i in range(N_LAYERS)]

    @property
    def device(self) -> torch.device:
        """The device the parameters live on."""
        return self._device

    @property
    def n_inputs(self) -> int:
        """Input (and output) width."""
        return self._sizes[0]

    def _weight(self, vector: torch.Tensor, layer: int) -> torch.Tensor:
        w_off, _, fan_in, fan_out = self._layout[layer]
        return vector[w_off : w_off + fan_in * fan_out].view(fan_out, fan_in)

    def _bias(self, vector: torch.Tensor, layer: int) -> torch.Tensor:
        _, b_off, _, fan_out = self._layout[layer]
        return vector[b_off : b_off + fan_out]

    def _check(self, x: np.ndarray) -> None:
        if x.ndim != 2 or x.shape[1] != self.n_inputs:
            raise ValueError(f"paths must have shape (N, {self.n_inputs}), got {x.shape}")

    def _forward(self, x: torch.Tensor, stop: int) -> list[torch.Tensor]:
        """Returns the activations of layers 0..stop, (B, units) each; [0] is `x`."""
        activations = [x]
        h = x
        for layer in range(stop):
            h = torch.addmm(self._biases[layer], h, self._weights_t[layer])
            if layer == BOTTLENECK - 1:
                h = torch.sigmoid(h)
            activations.append(h)
        return activations

    def encode(self, x: np.ndarray, *, chunk: int = 65536) -> np.ndarray:
        """Returns the bottleneck codes of `x` (N, 80), shape (N, 4) float64 in [0, 1].

        With the compiled loop the codes come from the same compiled layers as training,
        whose bits do not depend on the CPU (`algorithms.aurora_kernel`); elsewhere from
        torch on the device.
        """
        self._check(x)
        out = np.empty((x.shape[0], CODE_SIZE), dtype=np.float64)
        if self._compiled:
            data = np.ascontiguousarray(x, dtype=np.float32)
            work = epoch_workspace(self._sizes, ENCODE_COLUMNS)[0]
            sizes = np.array(self._sizes, dtype=np.int64)
            encode_batch(self._theta.numpy(), data, sizes, BOTTLENECK, work, out)
            return out
        with torch_threads(self._threads):
            for start in range(0, x.shape[0], chunk):
                batch = torch.as_tensor(x[start : start + chunk], dtype=torch.float32)
                code = self._forward(batch.to(self._device), BOTTLENECK)[-1]
                out[start : start + chunk] = code.cpu().numpy()
        return out

    def reconstruct(self, x: np.ndarray) -> np.ndarray:
        """Returns the network's output for `x` (N, 80), shape (N, 80) float32."""
        self._check(x)
        batch = torch.as_tensor(x, dtype=torch.float32).to(self._device)
        with torch_threads(self._threads):
            return self._forward(batch, N_LAYERS)[-1].cpu().numpy()

    def loss(self, x: np.ndarray) -> float:
        """Returns the mean absolute reconstruction error over `x` (N, 80)."""
        diff = self.reconstruct(x).astype(np.float64) - np.asarray(x, np.float64)
        return float(np.mean(np.abs(diff)))

    def _step(self, xb: torch.Tensor, learning_rate: float) -> None:
        """Takes one Adagrad step on the mean absolute error of the batch `xb` (B, 80)."""
        acts = self._forward(xb, N_LAYERS)
        diff = acts[-1] - xb
        g = torch.sign(diff).div_(diff.numel())
        for layer in range(N_LAYERS - 1, -1, -1):
            if layer == BOTTLENECK - 1:
                s = acts[layer + 1]
                g = g * (s - s * s)
            torch.mm(g.t(), acts[layer], out=self._grad_weights[layer])
            torch.sum(g, dim=0, out=self._grad_biases[layer])
            if layer > 0:
                g = torch.mm(g, self._weights[layer])
        self._accumulator.addcmul_(self._grad, self._grad)
        torch.sqrt(self._accumulator, out=self._denominator).add_(EPSILON)
        self._theta.addcdiv_(self._grad, self._denominator, value=-learning_rate)

    def train(
        self,
        x: np.ndarray,
        *,
        epochs: int,
        batch_size: int,
        learning_rate: float,
        seed: int,
    ) -> TrainingResult:
        """Trains on `x` (N, 80) and returns the loss before and after.

        Each epoch visits the paths in a fresh random order (a `torch.Generator` seeded by
        `seed`, on the CPU whatever the device, so the order never depends on it) in
        batches of `batch_size`, the last one possibly smaller, as Keras's `fit` does.

        Raises:
            ValueError: when `x` is not (N, 80) with N > 0, or a setting is not positive.
        """
        self._check(x)
        if x.shape[0] == 0:
            raise ValueError("training needs at least one path, got none")
        if epochs < 0 or batch_size < 1 or not learning_rate > 0.0:
            raise ValueError(
                f"need epochs >= 0, batch_size >= 1, learning_rate > 0; got {epochs}, "
                f"{batch_size}, {learning_rate}"
            )
        initial = self.loss(x)
        n = x.shape[0]
        generator = torch.Generator().manual_seed(int(seed))
        if self._compiled:
            self._train_compiled(x, epochs, batch_size, learning_rate, generator)
        else:
            data = torch.as_tensor(x, dtype=torch.float32).to(self._device)
            with torch_threads(self._threads):
                for _ in range(epochs):
                    order = torch.randperm(n, generator=generator).to(self._device)
                    for start in range(0, n, batch_size):
                        self._step(data[order[start : start + batch_size]], learning_rate)
        return TrainingResult(
            initial_loss=initial,
            final_loss=self.loss(x),
            n_samples=n,
            n_steps=epochs * -(-n // batch_size),
        )

    def _train_compiled(
        self,
        x: np.ndarray,
        epochs: int,
        batch_size: int,
        learning_rate: float,
        generator: torch.Generator,
    ) -> None:
        """Runs `epochs` compiled epochs on x (N, 80), in torch's batch order."""
        theta = self._theta.numpy()  # CPU tensors share their memory with these views
        accumulator = self._accumulator.numpy()
        data = np.ascontiguousarray(x, dtype=np.float32)
        sizes = np.array(self._sizes, dtype=np.int64)
        work = epoch_workspace(self._sizes, batch_size)
        lr, eps = np.float32(learning_rate), np.float32(EPSILON)
        for _ in range(epochs):
            order = torch.randperm(data.shape[0], generator=generator).numpy()
            train_epoch(
                theta, accumulator, data, order, batch_size, lr, eps, sizes, BOTTLENECK, *work
            )

    def state_dict(self) -> dict[str, torch.Tensor]:
        """Returns the weights, biases and Adagrad sums as named CPU tensors.

        `"layers.<i>.weight"` (out, in) and `"layers.<i>.bias"` (out,) for the ten Linear
        layers i = 0..9 (`reference_module(state)` builds the matching `nn.Sequential`);
        `"adagrad_sum"` holds the optimiser state, flat (P,): P the weights and biases of
        all ten layers.
        """
        theta = self._theta.detach().cpu()
        state = {}
        for layer in range(N_LAYERS):
            state[f"layers.{layer}.weight"] = self._weight(theta, layer).clone()
            state[f"layers.{layer}.bias"] = self._bias(theta, layer).clone()
        state["adagrad_sum"] = self._accumulator.detach().cpu().clone()
        return state

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        """Restores what `state_dict` gave back.

        Raises:
            ValueError: naming the first missing or misshapen entry.
        """
        theta = torch.empty(self._n_parameters, dtype=torch.float32)
        for layer in range(N_LAYERS):
            for name, view in (
                (f"layers.{layer}.weight", self._weight(theta, layer)),
                (f"layers.{layer}.bias", self._bias(theta, layer)),
            ):
                if name not in state or tuple(state[name].shape) != tuple(view.shape):
                    got = tuple(state[name].shape) if name in state else "missing"
                    raise ValueError(
                        f"encoder state {name!r}: expected {tuple(view.shape)}, got {got}"
                    )
                view.copy_(state[name])
        accumulator = state.get("adagrad_sum")
        if accumulator is None or tuple(accumulator.shape) != (self._n_parameters,):
            got = "missing" if accumulator is None else tuple(accumulator.shape)
            raise ValueError(
                f"encoder state 'adagrad_sum': expected ({self._n_parameters},), got {got}"
            )
        self._bind(theta, accumulator)
