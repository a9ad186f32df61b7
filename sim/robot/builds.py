"""Provides `lego_builds` and `build_lengths`: the LEGO build of every linkage of a batch at
once, in about a tenth of a millisecond a linkage: the build every leg is made of (the walk,
`linkevo pull`, a walk map) and the learned walk model's inputs (`sim.robot.walk_features`).

A leg walks as it is built, and its whole-module rounding moves its foot path (beams of 2
to 4 modules rounded by up to half a module). `sim.linkage.kernels.rounding` finds, by a
depth-first search, a rounding that turns over the whole turn with rigid beams and keeps
its foot path close: the closest of all (what simulating every rounding, up to 32,768 at
0.03-0.2 s a linkage, finds: `sim.robot.lego.closest_build`) for 94-99.5 % of study
linkages, one nearly as close for the rest. Where the search finds none (a few per
thousand), `sim.robot.lego.whole_module_build` tries every rounding, and a batch's feature
rows stand in with the linkage as evolved, as a walk map does.
"""

from __future__ import annotations

import numpy as np

from linkevo.sim.linkage.decoding import LinkageBatch, with_lengths
from linkevo.sim.linkage.kernels.geometry import crank_angles
from linkevo.sim.linkage.kernels.rounding import round_batch
from linkevo.sim.linkage.kinematics import Motion, simulate, take_rows
from linkevo.sim.study import DEFAULT_ANGLES

COARSE_ANGLES = 8
"""Roundings are ranked at about this many of the turn's crank angles, evenly spaced (the
same angles, bit for bit, as the whole turn's): the closest there is the closest over the
turn for 142 of 150 study linkages, and 1.2 mm further at most for the others."""

KEEP = (8, 128)
"""Closest foot-beam roundings tried, in order: the first search keeps few (the fewer
kept, the more of the search is cut off), the linkages it does not build are searched
again keeping more; those still not built count as not built."""


def lego_builds(
    batch: LinkageBatch, here: Motion | None = None, lengths: np.ndarray | None = None
) -> tuple[LinkageBatch, np.ndarray]:
    """Returns the batch (N linkages) as built with whole-module beams, and built (N,)
    bool: False where no rounding was found and the row is the linkage as evolved.
    `here` is the batch's motion over `DEFAULT_ANGLES` and `lengths` its (N, 15)
    `build_lengths`, where the caller has them."""
    lengths = build_lengths(batch, here) if lengths is None else lengths
    built = lengths[:, 0] > 0
    return with_lengths(batch, np.where(built[:, None], lengths, batch.beam_length)), built


def build_lengths(batch: LinkageBatch, here: Motion | None = None) -> np.ndarray:
    """Returns (N, 15) the whole-module beam lengths of each linkage's build (beam order,
    -1 past its beams), -1 in every column where the search found none. `here` is the
    batch's motion over `DEFAULT_ANGLES`, where the caller has it."""
    here = simulate(batch, DEFAULT_ANGLES) if here is None else here
    lengths = _round(batch, here, KEEP[0])
    for keep in KEEP[1:]:
        todo = np.flatnonzero(lengths[:, 0] < 0)
        if len(todo):
            lengths[todo] = _round(take_rows(batch, todo), take_rows(here, todo), keep)
    return lengths


def study_rows(
    batch: LinkageBatch, motion: Motion, rows: np.ndarray
) -> tuple[LinkageBatch, Motion]:
    """Returns a batch's `rows` and their motion over the study's `DEFAULT_ANGLES`: the
    batch's own motion, simulated again only when its crank angles are not the study's."""
    batch = take_rows(batch, rows)
    if motion.valid.shape[1] == DEFAULT_ANGLES:
        return batch, take_rows(motion, rows)
    return batch, simulate(batch, DEFAULT_ANGLES)


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
