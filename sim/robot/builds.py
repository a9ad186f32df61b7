"""Provides `lego_builds`: the LEGO build of every linkage of a batch at once, in about a
tenth of a millisecond a linkage (the learned walk model's inputs, `sim.robot.walk_features`).

A leg walks as it is built, and its whole-module rounding moves its foot path (beams of 2
to 4 modules rounded by up to half a module), so the walk model reads the build, not the
linkage as evolved. `sim.robot.lego.quantise` finds the build by simulating every rounding (up
to 32,768, 0.03-0.2 s a linkage); `sim.linkage.kernels.rounding` finds the same rounding by a
depth-first search for 94-99.5 % of study linkages (the rest: a rounding nearly as close,
or, in a few per thousand, none found, where the linkage as evolved stands in, as in a
walk map).
"""

from __future__ import annotations

import numpy as np

from linkevo.sim.linkage.decoding import LinkageBatch, with_lengths
from linkevo.sim.linkage.kernels.geometry import crank_angles
from linkevo.sim.linkage.kernels.rounding import round_batch
from linkevo.sim.linkage.kinematics import Motion, simulate, take_rows
from linkevo.sim.robot.lego import COARSE_ANGLES
from linkevo.sim.study import DEFAULT_ANGLES

KEEP = (8, 128)
"""Closest foot-beam roundings tried, in order: the first search keeps few (the fewer
kept, the more of the search is cut off), the linkages it does not build are searched
again keeping more; those still not built count as not built."""


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
        batch.node_int,
        batch.node_float,
        batch.beam_int,
        batch.n_beams,
        batch.beam_length,
        here.foot,
        batch.mode == "legacy",
        np.ascontiguousarray(theta[every]),
        theta,
        np.ascontiguousarray(foot[..., 0]),
        np.ascontiguousarray(foot[..., 1]),
        np.ascontiguousarray(here.valid[:, every]),
        keep,
        lengths,
    )
    return lengths
