"""Provides `lego_builds`: the LEGO build of every linkage of a batch at once, in about a
tenth of a millisecond a linkage (the learned walk model's inputs, `sim.walk_features`),
and `with_lengths`: a batch with other beam lengths.

A leg walks as it is built, and its whole-module rounding moves its foot path (beams of 2
to 4 modules rounded by up to half a module), so the walk model reads the build, not the
linkage as evolved. `sim.lego.quantise` finds the build by simulating every rounding (up
to 32,768, 0.03-0.2 s a linkage); `sim.kernels.rounding` finds the same rounding by a
depth-first search for 94-99.5 % of study linkages (the rest: a rounding nearly as close,
or, in a few per thousand, none found, where the linkage as evolved stands in, as in a
walk map).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from linkevo.sim.decoding import NODE_KINDS, LinkageBatch
from linkevo.sim.kernels.geometry import crank_angles
from linkevo.sim.kernels.rounding import round_batch
from linkevo.sim.kinematics import Motion, simulate, take_rows
from linkevo.sim.study import DEFAULT_ANGLES

COARSE_ANGLES = 8
"""Crank angles the roundings are ranked at (`sim.lego.COARSE_ANGLES`)."""
KEEP = (8, 128)
"""Closest foot-beam roundings tried, in order: the first search keeps few (the fewer
kept, the more of the search is cut off), the linkages it does not build are searched
again keeping more; those still not built count as not built."""
_TRIANGLE, _EXTENSION, _CRANK = (NODE_KINDS.index(k) for k in ("triangle", "extension", "crank"))


def lego_builds(batch: LinkageBatch, here: Motion | None = None) -> tuple[LinkageBatch, np.ndarray]:
    """Returns the batch (N linkages) as built with whole-module beams, and built (N,)
    bool: False where no rounding was found and the row is the linkage as evolved.
    `here` is the batch's motion over `DEFAULT_ANGLES`, where the caller has it."""
    here = simulate(batch, DEFAULT_ANGLES) if here is None else here
    lengths = _round(batch, here, KEEP[0])
    for keep in KEEP[1:]:
        todo = np.flatnonzero(lengths[:, 0] < 0)
        if len(todo):
            lengths[todo] = _round(take_rows(batch, todo), take_rows(here, todo), keep)
    built = lengths[:, 0] > 0
    return with_lengths(batch, np.where(built[:, None], lengths, batch.beam_length)), built


def _round(batch: LinkageBatch, here: Motion, keep: int) -> np.ndarray:
    """Returns (N, 15) `round_batch`'s lengths of the batch, whose motion is `here`."""
    every = np.arange(0, DEFAULT_ANGLES, DEFAULT_ANGLES // COARSE_ANGLES)
    foot = here.positions[np.arange(len(batch)), here.foot][:, every]  # (N, C, 2)
    theta = crank_angles(DEFAULT_ANGLES, batch.mode == "legacy")
    lengths = np.empty((len(batch), batch.beam_length.shape[1]))
    round_batch(
        batch.node_int, batch.node_float, batch.beam_int, batch.n_beams, batch.beam_length,
        here.foot, batch.mode == "legacy", np.ascontiguousarray(theta[every]), theta,
        np.ascontiguousarray(foot[..., 0]), np.ascontiguousarray(foot[..., 1]),
        np.ascontiguousarray(here.valid[:, every]), keep, lengths,
    )  # fmt: skip
    return lengths


def with_lengths(batch: LinkageBatch, lengths: np.ndarray) -> LinkageBatch:
    """Returns the batch (N linkages) with beam lengths (N, 15) put into its node
    parameters: the crank's, each extension's length, each triangle's l1 and l2 and its
    backup point (which exists only where l1 == l2, as `sim.decoding` writes it)."""
    n = len(batch)
    present = np.arange(lengths.shape[1])[None, :] < batch.n_beams[:, None]
    lengths = np.where(present, lengths, 0.0)
    ends = np.where(present, batch.beam_int[:, :, 1], -1)
    # each node's first and second beam (those that place it), -1 where none
    first = np.full((n, batch.node_int.shape[1]), -1)
    second = first.copy()
    for b in range(lengths.shape[1] - 1, -1, -1):  # last first, so the earliest stays first
        rows = np.flatnonzero(ends[:, b] >= 0)
        node = ends[rows, b]
        second[rows, node] = first[rows, node]
        first[rows, node] = b
    node_float = batch.node_float.copy()
    rows = np.arange(n)
    kind = batch.node_int[:, :, 0]
    for j in range(node_float.shape[1]):
        one = ((kind[:, j] == _CRANK) | (kind[:, j] == _EXTENSION)) & (first[:, j] >= 0)
        node_float[one, j, 0] = lengths[rows[one], first[one, j]]
        tri = (kind[:, j] == _TRIANGLE) & (second[:, j] >= 0)
        l1 = lengths[rows[tri], first[tri, j]]
        l2 = lengths[rows[tri], second[tri, j]]
        angle = node_float[tri, j, 2]
        node_float[tri, j, 0] = l1
        node_float[tri, j, 1] = l2
        node_float[tri, j, 3] = np.where(l1 == l2, l1 * np.cos(angle), 0.0)
        node_float[tri, j, 4] = np.where(l1 == l2, l1 * np.sin(angle), 0.0)
    return dataclasses.replace(batch, node_float=node_float, beam_length=lengths)
