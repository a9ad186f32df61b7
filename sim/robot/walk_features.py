"""Provides `walk_features`: what is known of a linkage's walk without physics, as the
learned walk model's input (`algorithms.walk_model`).

A walk is decided by where the foot goes (its path over the turn, in the leg's own frame
as the robot carries it), by what else of the leg comes near the floor, by how hard the
mechanism is to drive, and by how the two tripods share the body. The leg that walks is
the LEGO build, whose whole-module rounding moves the foot path (beams of 2-4 modules
rounded by up to half a module), so every feature is of the build (`sim.robot.builds`: the
rounding `linkevo pull` builds, found for a whole batch at once; the linkage as evolved
where none is found). All of it comes from the 2-D kernel at the study's 40 crank angles,
for a whole repertoire at once (no MuJoCo: 10,000 cells in one to two seconds).

The features of one linkage (`FEATURE_NAMES`, in modules or degrees), of its build:
- the foot path, x then y at each of the 40 angles, relative to the motor axle, mirrored so
  that the stance (the lower half of the path) moves towards +x, as the robot mounts
  every leg (`sim.robot.leg.Leg.facing`); 0 where an angle fails;
- the path's size and place: its x and y extent, lowest and highest y, the stance stroke
  (x extent of the lower half), mean x and y, how far below the foot's lowest point any
  other node reaches (another part touching the floor), the share of angles assembled;
- the mechanism: crank length, number of beams, total and longest beam, the physical
  checks (smallest transmission angle, toggle passages, largest stretch, width, height);
- the rounding: the evolved beams' total and largest distance from a whole number of
  modules, the mean distance of the build's foot path from the evolved one's, and whether
  a build was found (1) or the linkage as evolved stands in (0);
- a quasi-static tripod gait: two copies of the path half a turn apart, the lower foot
  carrying the body and pushing it by its own horizontal step: the advance per turn, the
  body's rise and fall, the share of the turn both feet are within 0.25 modules of each
  other, the steps the carrying foot takes backwards, the largest drop at a hand-over.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from linkevo.sim.linkage.decoding import LinkageBatch, decode
from linkevo.sim.linkage.kinematics import Motion, simulate
from linkevo.sim.linkage.physical import physical_checks, quiet_all_nan
from linkevo.sim.robot.builds import lego_builds, study_rows
from linkevo.sim.robot.walk_rows import FLOOR_ORDER, Status, credited_cm
from linkevo.sim.study import DEFAULT_ANGLES

if TYPE_CHECKING:
    import pandas as pd

FEATURES_VERSION = "linkevo.walk-features/2"
"""What `walk_features` computes; a walk model records it and refuses other inputs."""
STANCE_BANDS: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0)
"""Heights above the foot's lowest point (modules) within which it counts as down: per band,
the share of the turn it is down (duty), its x extent while down (stroke) and the share of
that time it moves backwards."""
SCALARS: tuple[str, ...] = (
    "path_width",
    "path_height",
    "path_low",
    "path_high",
    "stance_stroke",
    "path_mean_x",
    "path_mean_y",
    "reach_below_foot",
    "assembled_share",
    "crank_length",
    "n_beams",
    "beams_total",
    "beam_longest",
    "min_transmission_deg",
    "toggle_passages",
    "max_stretch",
    "width",
    "height",
    "rounding_total",
    "rounding_largest",
    "build_shift",
    "built",
    *(f"{what}_{h:g}" for h in STANCE_BANDS for what in ("duty", "stroke", "backwards")),
    "tripod_advance",
    "tripod_bob",
    "tripod_both_down",
    "tripod_backwards",
    "tripod_drop",
)
FEATURE_NAMES: tuple[str, ...] = (
    *(f"foot_x_{k}" for k in range(DEFAULT_ANGLES)),
    *(f"foot_y_{k}" for k in range(DEFAULT_ANGLES)),
    *SCALARS,
)
"""The columns of `walk_features`, in order."""


def walk_features(genomes: np.ndarray, mode: str = "paper") -> np.ndarray:
    """Returns (N, len(FEATURE_NAMES)) float32 features of genomes (N, 56) in `mode`."""
    genomes = np.asarray(genomes, dtype=np.float64).reshape(-1, 56)
    evolved = decode(genomes, mode)
    return features_of(evolved, simulate(evolved, DEFAULT_ANGLES))


def features_of_rows(batch: LinkageBatch, motion: Motion, rows: np.ndarray) -> np.ndarray:
    """Returns `walk_features` (len(rows), F) of a batch's `rows` from the batch's own
    decoding and motion (`sim.robot.builds.study_rows`)."""
    return features_of(*study_rows(batch, motion, rows))


@quiet_all_nan
def features_of(
    evolved: LinkageBatch, before: Motion, searched: np.ndarray | None = None
) -> np.ndarray:
    """Returns `walk_features` of decoded linkages (N) from their motion at the study's
    `DEFAULT_ANGLES` and, where the caller has them, their builds' (N, 15) lengths
    (`sim.robot.builds.build_lengths`): a walking trial's round decodes, simulates and
    builds each candidate once for its features and its walk."""
    n = len(evolved)
    if not n:
        return np.zeros((0, len(FEATURE_NAMES)), np.float32)
    batch, built = lego_builds(evolved, before, searched)
    motion = simulate(batch, DEFAULT_ANGLES)
    checks = physical_checks(batch, motion, rigid=built)
    rows = np.arange(n)
    pos = motion.positions - motion.positions[:, :1]  # (N, 12, A, 2) from the motor axle
    path = pos[rows, motion.foot]  # (N, A, 2)
    valid = motion.valid
    y = np.where(valid, path[..., 1], np.nan)
    low = y <= ((np.nanmin(y, axis=1) + np.nanmax(y, axis=1)) / 2)[:, None]
    step = np.diff(path[..., 0], axis=1, append=path[:, :1, 0])
    facing = np.where(np.nansum(np.where(low & valid, step, 0.0), axis=1) >= 0, 1.0, -1.0)
    x = np.where(valid, path[..., 0] * facing[:, None], np.nan)
    stance = np.where(low, x, np.nan)
    lengths = batch.beam_length
    present = np.arange(lengths.shape[1])[None, :] < batch.n_beams[:, None]
    original = evolved.beam_length
    rounding = np.where(present, np.abs(original - np.round(np.maximum(original, 1.0))), 0.0)
    shift = np.hypot(*(before.positions[rows, motion.foot] - path).transpose(2, 0, 1))
    others = np.where(valid[:, None, :], pos[..., 1], np.nan)
    scalars = np.stack(
        [
            np.nanmax(x, axis=1) - np.nanmin(x, axis=1),
            np.nanmax(y, axis=1) - np.nanmin(y, axis=1),
            np.nanmin(y, axis=1),
            np.nanmax(y, axis=1),
            np.nanmax(stance, axis=1) - np.nanmin(stance, axis=1),
            np.nanmean(x, axis=1),
            np.nanmean(y, axis=1),
            np.nanmin(y, axis=1) - np.fmin.reduce(others.reshape(n, -1), axis=1),
            valid.mean(axis=1),
            lengths[:, 0],
            batch.n_beams.astype(float),
            np.where(present, lengths, 0.0).sum(axis=1),
            np.where(present, lengths, 0.0).max(axis=1),
            checks.min_transmission_deg,
            checks.toggle_passages.astype(float),
            checks.max_stretch,
            checks.size_modules[:, 0],
            checks.size_modules[:, 1],
            rounding.sum(axis=1),
            rounding.max(axis=1),
            np.nanmean(shift, axis=1),
            built.astype(float),
            *_stance_bands(x, y, valid),
            *_tripod(x, y),
        ],
        axis=1,
    )
    out = np.concatenate([x, y, scalars], axis=1)
    return np.nan_to_num(out, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32)


def _stance_bands(x: np.ndarray, y: np.ndarray, valid: np.ndarray) -> list[np.ndarray]:
    """Per `STANCE_BANDS` height: duty, stroke and backwards share of paths x, y (N, A)."""
    low = np.nanmin(y, axis=1)[:, None]
    step = np.diff(x, axis=1, append=x[:, :1])  # towards the next angle
    out = []
    for h in STANCE_BANDS:
        down = valid & (y <= low + h)
        xs = np.where(down, x, np.nan)
        count = down.sum(axis=1)
        out += [
            down.mean(axis=1),
            np.nanmax(xs, axis=1) - np.nanmin(xs, axis=1),
            np.where(down & (step < 0), 1.0, 0.0).sum(axis=1) / np.maximum(count, 1),
        ]
    return out


def _tripod(x: np.ndarray, y: np.ndarray) -> list[np.ndarray]:
    """Returns the quasi-static tripod gait's advance per turn, bob, both-down share,
    backward steps and largest hand-over drop (each (N,), modules or a share) of paths
    x, y (N, A) (NaN at failed angles): the second tripod's foot is half a turn behind."""
    half = x.shape[1] // 2
    xb, yb = np.roll(x, half, axis=1), np.roll(y, half, axis=1)
    first = y <= yb  # the first tripod carries the body
    step = np.where(first, np.roll(x, -1, axis=1) - x, np.roll(xb, -1, axis=1) - xb)
    height = -np.minimum(y, yb)
    carried = np.nansum(step, axis=1)
    handover = first != np.roll(first, -1, axis=1)
    rise = np.abs(np.roll(height, -1, axis=1) - height)
    return [
        np.abs(carried),
        np.nanmax(height, axis=1) - np.nanmin(height, axis=1),
        np.nanmean(np.abs(y - yb) < 0.25, axis=1),
        np.nansum(np.clip(-np.sign(carried)[:, None] * step, 0.0, None), axis=1),
        np.nanmax(np.where(handover, rise, 0.0), axis=1),
    ]


def walk_targets(walks: pd.DataFrame, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Returns what walk rows (`sim.robot.walk_rows.WalkRow`) say of `cells` (N,) on each of
    `FLOOR_ORDER`, what the walk model learns: distance (N, 2) cm per 10 s, credited at
    most the level-body bound (`sim.robot.walk_rows.credited_cm`), NaN where not walked there
    or broken; breaks (N, 2) 1.0 or 0.0, NaN where not walked there (not buildable,
    skipped, failed: such a row teaches nothing)."""
    at = {int(c): i for i, c in enumerate(cells)}
    distance = np.full((len(cells), len(FLOOR_ORDER)), np.nan)
    breaks = np.full((len(cells), len(FLOOR_ORDER)), np.nan)
    walked = walks[(walks["status"] == Status.WALKED) & walks["cell"].isin(at)]
    for row in walked.to_dict("records"):
        if row["floor"] not in FLOOR_ORDER:
            continue
        i, k = at[int(row["cell"])], FLOOR_ORDER.index(row["floor"])
        breaks[i, k] = float(bool(row["breaks"]))
        if not row["breaks"]:
            distance[i, k] = credited_cm(row)
    return distance, breaks
