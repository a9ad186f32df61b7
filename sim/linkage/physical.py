"""Provides PhysicalChecks and `physical_checks`: what a builder needs to know of a linkage
beyond its loss, over one crank turn, for a batch.

- **Turns fully**: every sampled crank angle assembled (no failed angle).
- **Transmission angle** at each triangle joint P (beams P-A and P-C): the angle between
  the two beams, folded to [0, 90] degrees (min(t, 180 - t)). Near 0 the two beams are
  collinear: the joint is at a toggle position, where a built linkage can jam or take the
  other assembly branch.
- **Toggle passages**: crank angles at which some triangle joint's transmission angle is
  below `TOGGLE_DEG`.
- **Stretch**: the largest |distance(start, end) - length| of any beam at any assembled
  angle. The simulation accepts a triangle whose anchors are up to the tolerance (0.1)
  too far apart or too close (spec §2) and places the joint as if they were not; a rigid
  beam cannot do that, so a linkage with a stretch above a few hundredths of a module
  does not move as simulated.
- **Size**: width and height in modules of the box every node sweeps over the turn.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass

import numpy as np

from linkevo.sim.linkage.decoding import NODE_KINDS, LinkageBatch
from linkevo.sim.linkage.kinematics import Motion, take_rows

TOGGLE_DEG = 5.0
"""A transmission angle below this is a toggle position."""
BUILDABLE_STRETCH = 0.02
"""Largest beam stretch (modules) that a built linkage absorbs in its pin clearance."""


@dataclass(frozen=True)
class PhysicalChecks:
    """The checks of N linkages.

    Attributes:
        turns_fully: (N,) bool, every sampled angle assembled.
        min_transmission_deg: (N,) float64, the smallest transmission angle of any triangle
            joint over the turn (90 where the linkage has no triangle; NaN if it never
            assembles).
        toggle_passages: (N,) int64, assembled angles with a transmission angle below
            TOGGLE_DEG.
        max_stretch: (N,) float64, the largest beam stretch, modules (NaN if it never
            assembles).
        size_modules: (N, 2) float64, width and height of the swept box, modules.
    """

    turns_fully: np.ndarray
    min_transmission_deg: np.ndarray
    toggle_passages: np.ndarray
    max_stretch: np.ndarray
    size_modules: np.ndarray

    @property
    def buildable(self) -> np.ndarray:
        """(N,) bool: turns fully, passes no toggle and stretches no beam beyond
        BUILDABLE_STRETCH."""
        return (
            self.turns_fully
            & (self.toggle_passages == 0)
            & (np.nan_to_num(self.max_stretch, nan=np.inf) <= BUILDABLE_STRETCH)
        )

    def row(self, i: int) -> dict[str, float | int | bool]:
        """Returns linkage i's checks as JSON-able values (None where a value is NaN: a
        linkage that never assembles)."""

        def number(value: float) -> float | None:  # JSON has no NaN
            return None if np.isnan(value) else float(value)

        return {
            "turns_fully": bool(self.turns_fully[i]),
            "min_transmission_deg": number(self.min_transmission_deg[i]),
            "toggle_passages": int(self.toggle_passages[i]),
            "max_stretch": number(self.max_stretch[i]),
            "width_modules": number(self.size_modules[i, 0]),
            "height_modules": number(self.size_modules[i, 1]),
            "buildable": bool(self.buildable[i]),
        }


def quiet_all_nan(function):
    """Runs `function` without numpy's all-NaN warnings (linkages or angles that never
    assemble)."""

    @functools.wraps(function)
    def quiet(*args, **kwargs):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return function(*args, **kwargs)

    return quiet


@quiet_all_nan
def max_stretch(batch: LinkageBatch, motion: Motion) -> np.ndarray:
    """Returns (N,) the largest beam stretch of each linkage, modules (NaN if it never
    assembles)."""
    pos = motion.positions  # (N, 12, A, 2), NaN at failed angles
    rows = np.arange(pos.shape[0])[:, None]
    beam_start, beam_end = batch.beam_int[:, :, 0], batch.beam_int[:, :, 1]
    present = beam_start >= 0
    span = pos[rows, np.where(present, beam_end, 0)] - pos[rows, np.where(present, beam_start, 0)]
    length = np.sqrt(span[..., 0] ** 2 + span[..., 1] ** 2)  # (N, 15, A)
    stretch = np.abs(length - batch.beam_length[:, :, None])
    stretch = np.where(present[:, :, None], stretch, np.nan)
    return np.fmax.reduce(stretch.reshape(pos.shape[0], -1), axis=1)  # NaN-skipping max


@quiet_all_nan
def physical_checks(
    batch: LinkageBatch, motion: Motion, rigid: np.ndarray | None = None
) -> PhysicalChecks:
    """Returns the checks of decoded linkages and their simulated motion (N linkages).

    rigid: (N,) bool, rows known to keep every beam's length (a LEGO build that turns
    rigidly, `sim.robot.builds`): their stretch is 0 without measuring it."""
    pos = motion.positions  # (N, 12, A, 2), NaN at failed angles
    n = pos.shape[0]
    rows = np.arange(n)[:, None]
    if rigid is None:
        stretch = max_stretch(batch, motion)
    else:
        stretch = np.where(motion.valid.any(axis=1), 0.0, np.nan)
        measure = np.flatnonzero(~rigid)
        if len(measure):
            stretch[measure] = max_stretch(take_rows(batch, measure), take_rows(motion, measure))

    # Each triangle joint's transmission angle (N, T, A); T: the most triangles of any row.
    triangle = batch.node_int[:, :, 0] == NODE_KINDS.index("triangle")  # (N, 12)
    order = np.argsort(~triangle, axis=1, kind="stable")[:, : max(int(triangle.sum(1).max()), 1)]
    joint = np.take_along_axis(triangle, order, axis=1)  # (N, T) a real triangle
    node_int = np.take_along_axis(batch.node_int, order[:, :, None], axis=1)
    px, py = np.ascontiguousarray(pos[..., 0]), np.ascontiguousarray(pos[..., 1])  # (N, 12, A)
    joint_at = (rows, order)
    a_at = (rows, np.where(joint, node_int[:, :, 1], 0))
    c_at = (rows, np.where(joint, node_int[:, :, 2], 0))
    ux, uy = px[a_at] - px[joint_at], py[a_at] - py[joint_at]  # joint -> A, (N, T, A)
    vx, vy = px[c_at] - px[joint_at], py[c_at] - py[joint_at]  # joint -> C
    dot = ux * vx + uy * vy
    norms = np.sqrt(ux * ux + uy * uy) * np.sqrt(vx * vx + vy * vy)
    angle = np.degrees(np.arccos(np.clip(dot / norms, -1.0, 1.0)))  # (N, T, A)
    transmission = np.where(joint[:, :, None], np.minimum(angle, 180.0 - angle), np.inf)
    per_angle = np.where(np.isnan(transmission), np.inf, transmission).min(axis=1)  # (N, A)
    toggles = ((per_angle < TOGGLE_DEG) & motion.valid).sum(axis=1)
    lowest = per_angle.min(axis=1)
    min_transmission = np.where(motion.valid.any(axis=1), np.minimum(lowest, 90.0), np.nan)

    return PhysicalChecks(
        turns_fully=motion.valid.all(axis=1),
        min_transmission_deg=min_transmission,
        toggle_passages=toggles.astype(np.int64),
        max_stretch=stretch,
        size_modules=np.stack([_extent(px.reshape(n, -1)), _extent(py.reshape(n, -1))], axis=1),
    )


def _extent(values: np.ndarray) -> np.ndarray:
    """Returns (N,) the NaN-skipping max minus min of each row of values (N, K)."""
    return np.fmax.reduce(values, axis=1) - np.fmin.reduce(values, axis=1)
