"""Provides Motion and `simulate`: every node's trajectory over one crank turn."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from linkevo.sim.linkage import kernels
from linkevo.sim.linkage.decoding import LinkageBatch
from linkevo.sim.linkage.genome import MAX_BEAMS, N_NODES
from linkevo.sim.study import DEFAULT_ANGLES, MIN_ANGLES


@dataclass(frozen=True)
class Motion:
    """Trajectories of N linkages over A crank angles.

    Attributes:
        positions: (N, 12, A, 2) float64 node positions, NaN at failed angles.
        valid: (N, A) bool, True where the angle assembled.
        beam_angles: (N, 15, A) float64 recorded beam angles, NaN at failed angles and
            for absent beams.
        foot: (N,) int64 index of the foot node.
    """

    positions: np.ndarray
    valid: np.ndarray
    beam_angles: np.ndarray
    foot: np.ndarray

    @property
    def error(self) -> np.ndarray:
        """(N,) int64 number of failed angles."""
        return (~self.valid).sum(axis=1)


def check_angles(n_angles: int) -> int:
    """Returns n_angles if it is an int >= MIN_ANGLES, else raises ValueError."""
    bad = isinstance(n_angles, bool) or not isinstance(n_angles, int | np.integer)
    if bad or n_angles < MIN_ANGLES:
        raise ValueError(f"n_angles must be an integer >= {MIN_ANGLES}, got {n_angles!r}")
    return int(n_angles)


def simulate(
    batch: LinkageBatch, n_angles: int = DEFAULT_ANGLES, only: np.ndarray | None = None
) -> Motion:
    """Returns the motion of decoded linkages over n_angles crank angles (spec §3).

    Args:
        batch: the linkages (N).
        n_angles: crank angles per turn, A.
        only: the indices of the A angles to simulate (A' of them: the motion's columns);
            each angle's positions are the same, bit for bit, as in the whole turn's.
    """
    n_angles = check_angles(n_angles)
    theta = kernels.crank_angles(n_angles, batch.mode == "legacy")
    if only is not None:
        theta = np.ascontiguousarray(theta[only])
    n, a = len(batch), len(theta)
    motion = Motion(
        positions=np.empty((n, N_NODES, a, 2)),
        valid=np.empty((n, a), np.bool_),
        beam_angles=np.full((n, MAX_BEAMS, a), np.nan),
        foot=np.empty(n, np.int64),
    )
    kernels.simulate_batch(
        batch.node_int,
        batch.node_float,
        batch.beam_int,
        batch.n_beams,
        theta,
        batch.mode == "legacy",
        motion.positions,
        motion.valid,
        motion.beam_angles,
        motion.foot,
    )
    return motion


def take_rows(arrays, index: np.ndarray):
    """Returns the rows `index` of a LinkageBatch or Motion (every array field)."""
    return dataclasses.replace(
        arrays,
        **{
            f.name: getattr(arrays, f.name)[index]
            for f in dataclasses.fields(arrays)
            if isinstance(getattr(arrays, f.name), np.ndarray)
        },
    )
