"""Provides the npz-safe encoding of a numpy random Generator's state."""

from __future__ import annotations

import json

import numpy as np


def encode_rng(rng: np.random.Generator) -> np.ndarray:
    """Returns the generator's bit-generator state as a 0-d unicode array holding JSON."""
    return np.array(json.dumps(rng.bit_generator.state))


def decode_rng(state: np.ndarray) -> np.random.Generator:
    """Returns a generator restored from `encode_rng`'s output, continuing the same stream."""
    doc = json.loads(str(np.asarray(state)[()]))
    bit_generator = getattr(np.random, doc["bit_generator"])()
    bit_generator.state = doc
    return np.random.Generator(bit_generator)
