"""Provides the foot-path representations the AURORA autoencoder reads (spec §6)."""

from __future__ import annotations

import numpy as np

REPRESENTATIONS: tuple[str, ...] = ("raw", "centred", "minmax")
"""How a path becomes the network input; see `prepare_paths`."""
DEFAULT_SCALE = 15.0
"""Length units per input unit for "centred": the median valid random path is about 15
units wide, so most inputs land in [-2, 2]."""


def check_representation(representation: str) -> str:
    """Returns `representation` when it is known.

    Raises:
        ValueError: naming the bad value and the allowed ones.
    """
    if representation not in REPRESENTATIONS:
        raise ValueError(
            f"unknown path representation {representation!r}; allowed: {', '.join(REPRESENTATIONS)}"
        )
    return representation


def prepare_paths(
    foot_x: np.ndarray,
    foot_y: np.ndarray,
    representation: str = "raw",
    scale: float = DEFAULT_SCALE,
) -> np.ndarray:
    """Returns the autoencoder input of each foot path, shape (N, 2A) float32.

    The recorded samples (NaN marks a failed angle) are kept in angle order, then written
    x, y interleaved and zero-padded at the end to 2A values, as the published code
    does. Representations:

    - "raw": the coordinates as simulated (the paper's input).
    - "centred": minus the centroid of the recorded samples (the frame F_p compares paths
      in), divided by `scale`.
    - "minmax": each axis mapped to [0, 1] over the path's own samples (a flat axis maps
      to 0); size and aspect are lost.

    Args:
        foot_x: (N, A) foot path x, NaN at failed angles.
        foot_y: (N, A) foot path y, NaN at failed angles.
        representation: one of `REPRESENTATIONS`.
        scale: the "centred" divisor, > 0.

    Raises:
        ValueError: for an unknown representation, mismatched shapes or scale <= 0.
    """
    check_representation(representation)
    foot_x = np.asarray(foot_x, dtype=np.float64)
    foot_y = np.asarray(foot_y, dtype=np.float64)
    if foot_x.ndim != 2 or foot_x.shape != foot_y.shape:
        raise ValueError(
            f"foot_x and foot_y must be equal (N, A) arrays, got {foot_x.shape} and {foot_y.shape}"
        )
    if not scale > 0.0:
        raise ValueError(f"path scale must be > 0, got {scale!r}")
    n, n_angles = foot_x.shape
    recorded = ~(np.isnan(foot_x) | np.isnan(foot_y))
    xy = np.stack([foot_x, foot_y], axis=2)
    if representation == "centred":
        counts = np.maximum(recorded.sum(axis=1), 1)[:, None]
        centroid = np.where(recorded[:, :, None], xy, 0.0).sum(axis=1) / counts
        xy = (xy - centroid[:, None, :]) / scale
    elif representation == "minmax":
        lo = np.min(np.where(recorded[:, :, None], xy, np.inf), axis=1)
        span = np.max(np.where(recorded[:, :, None], xy, -np.inf), axis=1) - lo
        span = np.where(span > 0.0, span, np.inf)
        xy = (xy - lo[:, None, :]) / span[:, None, :]
    # Stable sort moves every row's recorded samples to the front, in angle order.
    order = np.argsort(~recorded, axis=1, kind="stable")
    packed = np.take_along_axis(xy, order[:, :, None], axis=1)
    keep = np.take_along_axis(recorded, order, axis=1)
    packed = np.where(keep[:, :, None], packed, 0.0)
    return packed.reshape(n, 2 * n_angles).astype(np.float32)


def valid_rows(error: np.ndarray) -> np.ndarray:
    """Returns the rows whose path has no failed angle (error == 0), (K,) int64."""
    return np.flatnonzero(np.asarray(error) == 0)
