"""Provides `AuroraSettings`: MAP-AU's autoencoder schedule and input, checked without
torch (a dry run checks them; only the device needs torch to resolve)."""

from __future__ import annotations

from dataclasses import dataclass, fields

from linkevo.algorithms.aurora_paths import check_representation

DEVICES: tuple[str, ...] = ("auto", "cpu", "cuda")
"""Where the autoencoder trains: "auto" takes a GPU when torch sees one, else the CPU."""


@dataclass(frozen=True)
class AuroraSettings:
    """The autoencoder's schedule and input; defaults are the paper's (spec §6).

    Attributes:
        initial_epochs: epochs of the initial training on the first batch's valid paths.
        retrain_epochs: epochs of each later training on the repertoire's valid paths.
        retrain_period: iterations between trainings (after iterations 10, 20, ...).
        ae_batch_size: paths per Adagrad step (Keras's default, 32, in the paper).
        learning_rate: Adagrad learning rate (Keras's default, 0.001, in the paper).
        representation: network input, "raw" (the paper's), "centred" or "minmax"; see
            `algorithms.aurora_paths.prepare_paths`.
        path_scale: length units per input unit for "centred".
        device: "auto", "cpu" or "cuda".
        threads: torch CPU threads while training and encoding (results are reproducible
            for a fixed thread count).
    """

    initial_epochs: int = 3000
    retrain_epochs: int = 1000
    retrain_period: int = 10
    ae_batch_size: int = 32
    learning_rate: float = 0.001
    representation: str = "raw"
    path_scale: float = 15.0
    device: str = "auto"
    threads: int = 1

    def __post_init__(self) -> None:
        for name in ("initial_epochs", "retrain_epochs"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
        for name in ("retrain_period", "ae_batch_size", "threads"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        for name in ("learning_rate", "path_scale"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
                raise ValueError(f"{name} must be a number > 0, got {value!r}")
        check_representation(self.representation)
        if self.device not in DEVICES:
            raise ValueError(f"unknown device {self.device!r}; allowed: {', '.join(DEVICES)}")

    @staticmethod
    def from_options(options: dict[str, object]) -> AuroraSettings:
        """Returns the settings named in `options` (the rest at their defaults).

        Raises:
            ValueError: naming an unknown option and the allowed ones, or a bad value.
        """
        allowed = [f.name for f in fields(AuroraSettings)]
        unknown = sorted(set(options) - set(allowed))
        if unknown:
            raise ValueError(
                f"unknown option(s) {', '.join(map(repr, unknown))} for MAP-AU; "
                f"allowed: initial_sigma, {', '.join(allowed)}"
            )
        return AuroraSettings(**options)  # type: ignore[arg-type]

    def resolved_device(self) -> str:
        """Returns the torch device to use: "auto" becomes "cuda" when available, else "cpu".

        Raises:
            ValueError: when "cuda" is asked for and torch sees no GPU.
        """
        import torch

        if self.device == "auto":
            return "cuda" if torch.cuda.is_available() else "cpu"
        if self.device == "cuda" and not torch.cuda.is_available():
            raise ValueError(
                "device 'cuda' was asked for but torch sees no GPU; use 'auto' or 'cpu'"
            )
        return self.device
