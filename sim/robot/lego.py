"""Provides `quantise`: a linkage rebuilt with whole-module beams (LEGO Technic), re-simulated.

A Technic beam's holes are one module apart, so every beam length must be a whole number
of modules (the frame's holes, the static nodes, already are). Rounding each beam on its
own can stop the linkage turning or move its foot path far; instead each length is
rounded down or up (at least 1 module) so that the linkage turns fully with exact
kinematics (no beam stretched by the spec's tolerance band: a rigid beam cannot stretch)
and its foot path stays close to the original's, in mean distance at `COARSE_ANGLES`
evenly spaced crank angles.

The build (`whole_module_build`, what every leg is made of) is the depth-first search's
rounding (`sim.robot.builds`, a tenth of a millisecond): the closest of all for 94-99.5 %
of study linkages, one nearly as close for the rest. `closest_build` simulates every
combination instead (a linkage has at most 15 beams, so at most 2^15 = 32,768 roundings,
each at the coarse angles as one batch; the closest then over the whole turn until one
turns with rigid beams), 0.03-0.2 s a linkage: the build where the search finds none, and
the rounding `quantise` takes at other crank-angle counts than the study's. The sheet's
shifts are measured over the whole turn, and its counts (roundings, feasible) are of every
combination.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass

import numpy as np

from linkevo.sim.errors import LinkevoError
from linkevo.sim.linkage import reference
from linkevo.sim.linkage.decoding import LinkageBatch, decode, with_lengths
from linkevo.sim.linkage.fitness import named_target
from linkevo.sim.linkage.kernels.codes import EXACT
from linkevo.sim.linkage.kinematics import Motion, simulate, take_rows
from linkevo.sim.linkage.physical import PhysicalChecks, max_stretch, physical_checks
from linkevo.sim.robot.builds import COARSE_ANGLES, build_lengths
from linkevo.sim.study import DEFAULT_ANGLES


class QuantiseError(LinkevoError, ValueError):
    """No whole-module rounding of the linkage turns fully; the message says how close any came."""


@dataclass(frozen=True)
class Quantised:
    """A linkage with whole-module beams.

    Attributes:
        lengths: (B,) int64 beam lengths in modules, beam order.
        original: (B,) float64 the linkage's beam lengths.
        batch: the rounded linkage (one row).
        motion: its simulation.
        checks: its physical checks.
        foot_x, foot_y: (A,) its foot path; original_x, original_y: (A,) the original's
            (NaN where the original fails).
        mean_shift, max_shift: mean and largest distance between the two paths (modules),
            over the angles where the original assembles.
        loss: the rounded linkage's loss under `fitness` (the spec's fitness, re-simulated).
        original_loss: the original's loss under the same fitness.
        roundings: how many roundings were simulated; feasible: how many turned fully
            with exact kinematics.
    """

    lengths: np.ndarray
    original: np.ndarray
    batch: LinkageBatch
    motion: Motion
    checks: PhysicalChecks
    foot_x: np.ndarray
    foot_y: np.ndarray
    original_x: np.ndarray
    original_y: np.ndarray
    mean_shift: float
    max_shift: float
    loss: float
    original_loss: float
    roundings: int
    feasible: int


def quantise(
    genome: np.ndarray, mode: str = "paper", fitness: str = "Fp", n_angles: int = DEFAULT_ANGLES
) -> Quantised:
    """Returns a linkage's build with whole-module beams (`whole_module_build`'s at the study's
    crank angles, `closest_build`'s at any other count) and its sheet's figures.

    Args:
        genome: (56,) the linkage.
        mode: "paper" or "legacy".
        fitness: "Fp" or "Fsl", for the two losses reported.
        n_angles: crank angles per turn.

    Raises:
        QuantiseError: when no rounding turns fully without stretching a beam.
    """
    chosen = None
    if n_angles == DEFAULT_ANGLES:
        chosen = _searched(decode(np.asarray(genome, dtype=np.float64).reshape(1, -1), mode))
    found = _closest_rounding(genome, mode, n_angles, chosen=chosen)
    seen = found.here.valid[0]
    x0, y0 = _foot_path(found.here, 0)
    x, y = _foot_path(found.motion, 0)
    return Quantised(
        lengths=found.lengths,
        original=found.original,
        batch=found.batch,
        motion=found.motion,
        checks=physical_checks(found.batch, found.motion),
        foot_x=x,
        foot_y=y,
        original_x=x0,
        original_y=y0,
        mean_shift=found.mean_shift,
        max_shift=float(np.max(np.hypot(x - x0, y - y0)[seen])),
        loss=_loss(genome, mode, fitness, n_angles, found.lengths),
        original_loss=_loss(genome, mode, fitness, n_angles, None),
        roundings=found.roundings,
        feasible=found.feasible,
    )


def whole_module_build(
    genome: np.ndarray, mode: str = "paper", searched: np.ndarray | None = None
) -> LinkageBatch:
    """Returns the linkage's build (one row): the depth-first search's rounding, or, where it
    finds none, `closest_build`'s.

    Args:
        genome: (56,) the linkage.
        mode: "paper" or "legacy".
        searched: (15,) the search's lengths where the caller has them (a row of
            `sim.robot.builds.build_lengths`, found for a whole batch at once).

    Raises:
        QuantiseError: when no rounding turns fully with rigid beams.
    """
    base = decode(np.asarray(genome, dtype=np.float64).reshape(1, -1), mode)
    chosen = _searched(base, searched)
    return closest_build(genome, mode) if chosen is None else _with_lengths(base, chosen[None])


def closest_build(genome: np.ndarray, mode: str = "paper") -> LinkageBatch:
    """Returns the rounding whose foot path is closest of all that turn with rigid beams
    (one row), every combination simulated.

    Raises:
        QuantiseError: when no rounding turns fully with rigid beams.
    """
    return _closest_rounding(genome, mode, DEFAULT_ANGLES, count_feasible=False).batch


def _searched(base: LinkageBatch, searched: np.ndarray | None = None) -> np.ndarray | None:
    """Returns (B,) int64 the depth-first search's build lengths of one decoded linkage's B
    beams (`searched`, its row of `build_lengths`, where the caller has it), or None
    where the search found none."""
    if searched is None:
        searched = build_lengths(base)[0]
    n_beams = int(np.count_nonzero(searched > 0))
    return searched[:n_beams].astype(np.int64) if n_beams else None


@dataclass(frozen=True)
class _Rounding:
    """The closest rounding that turns: its lengths (B,), batch and motion (one row), the
    original's lengths and motion, the mean foot-path shift, and the search's counts
    (`feasible` None when not counted)."""

    lengths: np.ndarray
    batch: LinkageBatch
    motion: Motion
    original: np.ndarray
    here: Motion
    mean_shift: float
    roundings: int
    feasible: int | None


def _closest_rounding(
    genome: np.ndarray,
    mode: str,
    n_angles: int,
    count_feasible: bool = True,
    chosen: np.ndarray | None = None,
) -> _Rounding:
    """Returns the whole-module rounding of the linkage that turns with rigid beams and
    keeps the foot path closest (`QuantiseError` when none does), or with the search's
    counts the `chosen` lengths (B,) where given (a rounding known to turn with rigid
    beams).

    Every rounding is simulated at `COARSE_ANGLES` of the turn's crank angles: one that
    fails at any of them cannot turn, and the others are ranked by their foot path's mean
    distance from the original's there (ties in product order). In that order, chunk by
    chunk, they are simulated over the whole turn, and the first that turns with rigid beams
    is the one; only `count_feasible` simulates them all, to count the rigid ones."""
    base = decode(np.asarray(genome, dtype=np.float64).reshape(1, -1), mode)
    here = simulate(base, n_angles)
    n_beams = int(base.n_beams[0])
    original = base.beam_length[0, :n_beams].copy()
    options = [_roundings(length) for length in original]
    combos = np.array(list(itertools.product(*options)), dtype=np.int64)  # (R, B)
    roundings = len(combos)
    every = np.arange(0, n_angles, max(1, n_angles // COARSE_ANGLES))
    coarse = simulate(_with_lengths(base, combos), n_angles, only=every)
    alive = np.flatnonzero(coarse.valid.all(axis=1))
    combos = combos[alive]
    order = np.argsort(_shifts(take_rows(coarse, alive), here, every), kind="stable")
    batch = _with_lengths(base, combos)
    stretch = np.full(len(combos), np.inf)
    turning = np.zeros(len(combos), dtype=bool)
    best, feasible = -1, 0
    for chunk in _chunks(order, count_feasible):
        motion = simulate(take_rows(batch, chunk), n_angles)
        turns = motion.valid.all(axis=1)
        turning[chunk] = turns
        if turns.any():
            stretch[chunk[turns]] = max_stretch(
                take_rows(batch, chunk[turns]), take_rows(motion, turns)
            )
        rigid = chunk[turns & (stretch[chunk] <= EXACT)]
        feasible += len(rigid)
        if best < 0 and len(rigid):
            best = int(rigid[0])
            if not count_feasible:
                break
    if best < 0:
        closest = float(stretch[turning].min()) if turning.any() else math.nan
        raise QuantiseError(
            f"no whole-module rounding of the {n_beams} beams turns fully with rigid beams: "
            f"of {roundings} roundings (each length down or up), {int(turning.sum())} turn "
            f"fully in simulation and the least stretch among them is {closest:.3f} modules"
        )
    lengths = combos[best] if chosen is None else chosen
    one = _with_lengths(base, lengths[None])
    motion = simulate(one, n_angles)
    return _Rounding(
        lengths=lengths,
        batch=one,
        motion=motion,
        original=original,
        here=here,
        mean_shift=float(_shifts(motion, here, np.arange(n_angles))[0]),
        roundings=roundings,
        feasible=feasible if count_feasible else None,
    )


def _shifts(motion: Motion, here: Motion, angles: np.ndarray) -> np.ndarray:
    """Returns (R,) each rounding's mean foot-path distance from the original's (modules)
    over `angles` (the motion's columns, indices into the original's turn) where the
    original assembles (0 where it assembles at none of them)."""
    x0, y0 = _foot_path(here, 0)
    seen = here.valid[0][angles]
    if not seen.any():
        return np.zeros(len(motion.foot))
    feet = motion.positions[np.arange(len(motion.foot)), motion.foot][:, seen]  # (R, A', 2)
    return np.hypot(feet[:, :, 0] - x0[angles][seen], feet[:, :, 1] - y0[angles][seen]).mean(1)


def _chunks(order: np.ndarray, whole: bool) -> list[np.ndarray]:
    """The roundings in the order they are simulated over the whole turn: chunks of 2,048,
    or, when the first that turns with rigid beams is all that is wanted, chunks growing
    from 8 (most linkages' closest rounding turns)."""
    if whole:
        return np.array_split(order, max(1, len(order) // 2048)) if len(order) else []
    out, start, size = [], 0, 8
    while start < len(order):
        out.append(order[start : start + size])
        start, size = start + size, min(size * 4, 2048)
    return out


def _roundings(length: float) -> tuple[int, ...]:
    low, high = max(math.floor(length), 1), max(math.ceil(length), 1)
    return (low,) if low == high else (low, high)


def _with_lengths(base: LinkageBatch, lengths: np.ndarray) -> LinkageBatch:
    """Returns R copies of a one-linkage batch with beam lengths (R, B) put into its
    node parameters (`sim.linkage.decoding.with_lengths`)."""
    r, n_beams = lengths.shape
    padded = np.zeros((r, base.beam_length.shape[1]))
    padded[:, :n_beams] = lengths
    return with_lengths(take_rows(base, np.zeros(r, dtype=np.int64)), padded)


def _foot_path(motion: Motion, i: int) -> tuple[np.ndarray, np.ndarray]:
    path = motion.positions[i, int(motion.foot[i])]
    return path[:, 0], path[:, 1]


def _loss(genome, mode: str, fitness: str, n_angles: int, lengths: np.ndarray | None) -> float:
    """The spec's loss of the linkage, with its beams set to `lengths` when given, computed
    by the plain reference simulator (which takes any beam lengths)."""
    linkage = reference.decode_linkage(np.asarray(genome, dtype=np.float64), mode)
    if lengths is not None:
        linkage = _reference_with_lengths(linkage, [float(v) for v in lengths])
    motion = reference.simulate_linkage(linkage, n_angles)
    return reference.losses(motion, fitness, mode, named_target("D16"))[0]


def _reference_with_lengths(linkage: reference.Linkage, lengths: list[float]):
    beams = tuple(
        dataclasses.replace(b, length=v) for b, v in zip(linkage.beams, lengths, strict=True)
    )
    by_end = {}
    for index, beam in enumerate(beams):
        by_end.setdefault(beam.end, []).append(index)
    blocks = []
    for block in linkage.blocks:
        placed = by_end[block.node]
        if isinstance(block, reference.Triangle):
            blocks.append(dataclasses.replace(block, l1=lengths[placed[0]], l2=lengths[placed[1]]))
        else:
            blocks.append(dataclasses.replace(block, length=lengths[placed[0]]))
    return dataclasses.replace(linkage, crank_length=lengths[0], blocks=tuple(blocks), beams=beams)
