"""Provides the reference's measures of a simulated linkage (spec §3-§5): the angle error,
the losses, the descriptors, and `evaluate_reference`, a batch as the kernel's `Evaluation`."""

from __future__ import annotations

import math

import numpy as np

from linkevo.sim.linkage.evaluation import Evaluation
from linkevo.sim.linkage.fitness import Target, named_target
from linkevo.sim.linkage.genome import validate_genomes
from linkevo.sim.linkage.reference.linkage import (
    CONTACT_BAND,
    CRANK_TIP,
    MOTOR,
    Extension,
    Linkage,
    Motion,
    check_mode,
    decode_linkage,
    distance,
    simulate_linkage,
)
from linkevo.sim.study import PATH_FITNESSES


def angle_error(motion: Motion, mode: str) -> float:
    """Returns F_ae: samples where the foot points upwards (spec §3).

    paper: their count; legacy: the summed distance from each such sample to the previous
    recorded sample (wrapping to the last). Zero when no beam ends at the foot.
    """
    path = [(float(x), float(y)) for x, y in motion.foot_path]
    total = 0.0
    for i, mean_angle in enumerate(motion.foot_angles):
        if 0.0 < mean_angle < math.pi:
            total += 1.0 if mode == "paper" else distance(path[i - 1], path[i])
    return total


def target_distances(path: np.ndarray, target: Target) -> tuple[float, float]:
    """Returns (D over step points, D over lift points) of a foot path (n, 2) (spec §4).

    D sums, over target points, the distance to the nearest path point, the path taken
    relative to its centroid.
    """
    n = len(path)
    cx = sum(float(x) for x, _ in path) / n
    cy = sum(float(y) for _, y in path) / n
    centred = [(float(x) - cx, float(y) - cy) for x, y in path]
    step = lift = 0.0
    for (tx, ty), is_step in zip(target.points.tolist(), target.is_step.tolist(), strict=True):
        nearest = min(distance((tx, ty), p) for p in centred)
        if is_step:
            step += nearest
        else:
            lift += nearest
    return step, lift


def step_and_lift(path: np.ndarray) -> tuple[float, float]:
    """Returns (F_s, F_l) of a foot path (n, 2), the paper's definition made precise in
    docs/simulator.md: stance length in the contact band and swing height."""
    xs = [float(x) for x, _ in path]
    ys = [float(y) for _, y in path]
    n = len(xs)
    y_min = min(ys)
    lowest = ys.index(y_min)
    dx = [xs[(i + 1) % n] - xs[i] for i in range(n)]
    sign = [(v > 0) - (v < 0) for v in dx]
    stance = sign[lowest] if sign[lowest] != 0 else 1
    in_band = [y - y_min <= CONTACT_BAND for y in ys]
    step = sum(
        abs(dx[i]) for i in range(n) if in_band[i] and in_band[(i + 1) % n] and sign[i] == stance
    )
    lift = max([0.0] + [ys[j] - y_min for j in range(n) if sign[j] == -stance])
    return step, lift


def decode_graph_parents(linkage: Linkage) -> list[list[int]]:
    """Returns each node's parents in the decode graph (docs/simulator.md, MAP-ST)."""
    parents: list[list[int]] = [[] for _ in range(CRANK_TIP)] + [[MOTOR]]
    for block in linkage.blocks:
        if isinstance(block, Extension):
            beam = linkage.beams[block.parent]
            parents.append([beam.start, beam.end])
        else:
            parents.append([block.anchor_a, block.anchor_c])
    return parents


def structure_descriptors(linkage: Linkage, foot: int) -> tuple[float, float, float]:
    """Returns (depth, drive size, moving share) of the foot, unscaled (docs/simulator.md)."""
    parents = decode_graph_parents(linkage)
    depth = [0] * len(parents)
    for node in range(CRANK_TIP, len(parents)):
        depth[node] = 1 + max(depth[p] for p in parents[node])

    def ancestors(node: int) -> set[int]:
        found = {node}
        for p in parents[node]:
            found |= ancestors(p)
        return found

    drive = ancestors(foot)
    moving = [n for n in drive if CRANK_TIP in ancestors(n)]
    return float(depth[foot]), float(len(drive)), len(moving) / len(drive)


def mean_beam_length(linkage: Linkage) -> float:
    """Returns m = mean((len - 2) * 10/13) over every beam, crank included."""
    scaled = [(beam.length - 2.0) * 10.0 / 13.0 for beam in linkage.beams]
    return sum(scaled) / len(scaled)


def descriptors(linkage: Linkage, motion: Motion) -> dict[str, list[float]]:
    """Returns the continuous MAP-WH, MAP-LIS and MAP-ST descriptors of one linkage."""
    path = motion.foot_path
    height = float(path[:, 1].max() - path[:, 1].min())
    width = float(path[:, 0].max() - path[:, 0].min())
    m = mean_beam_length(linkage)
    _, lift = step_and_lift(path)
    depth, drive, share = structure_descriptors(linkage, motion.foot)
    return {
        "MAP-WH": [height, width],
        "MAP-LIS": [m, lift],
        "MAP-ST": [m, depth * 10.0 / 9.0, drive * 10.0 / 13.0, share * 10.0],
    }


def losses(motion: Motion, fitness: str, mode: str, target: Target) -> list[float]:
    """Returns the loss of one motion: one value (Fp, Fsl) or two (Fp2, Fsl2) (spec §4)."""
    penalty = motion.error + angle_error(motion, mode)
    if fitness in ("Fp", "Fp2"):
        step, lift = target_distances(motion.foot_path, target)
        if fitness == "Fp":
            return [step + lift + penalty]
        return [step + penalty, lift + penalty]
    step, lift = step_and_lift(motion.foot_path)
    if fitness == "Fsl":
        return [-0.8 * step - 0.2 * lift + penalty]
    return [-step + penalty, -lift + penalty]


def evaluate_reference(
    genomes: np.ndarray,
    fitness: str = "Fp",
    mode: str = "paper",
    target: Target | None = None,
    n_angles: int = 40,
) -> Evaluation:
    """Returns the Evaluation of genomes (N, 56), one linkage at a time (as
    `sim.linkage.evaluating`)."""
    if fitness not in PATH_FITNESSES:
        raise ValueError(f"fitness must be one of {PATH_FITNESSES}, got {fitness!r}")
    check_mode(mode)
    if isinstance(n_angles, bool) or not isinstance(n_angles, int) or n_angles < 2:
        raise ValueError(f"n_angles must be an integer >= 2, got {n_angles!r}")
    target = named_target("D16") if target is None else target
    genomes = validate_genomes(genomes)
    rows = []
    for genome in genomes:
        linkage = decode_linkage(genome, mode)
        motion = simulate_linkage(linkage, n_angles)
        foot_xy = motion.positions[motion.foot]
        rows.append(
            (
                losses(motion, fitness, mode, target),
                motion.error,
                angle_error(motion, mode),
                motion.valid,
                motion.foot,
                foot_xy[:, 0],
                foot_xy[:, 1],
                descriptors(linkage, motion),
            )
        )
    n = len(rows)
    n_objectives = 1 if fitness in ("Fp", "Fsl") else 2
    loss = np.array([r[0] for r in rows], dtype=np.float64).reshape(n, n_objectives)
    return Evaluation(
        loss=loss[:, 0] if n_objectives == 1 else loss,
        error=np.array([r[1] for r in rows], dtype=np.int64),
        angle_error=np.array([r[2] for r in rows], dtype=np.float64),
        valid=np.array([r[3] for r in rows], dtype=bool).reshape(n, n_angles),
        foot=np.array([r[4] for r in rows], dtype=np.int64),
        foot_x=np.array([r[5] for r in rows], dtype=np.float64).reshape(n, n_angles),
        foot_y=np.array([r[6] for r in rows], dtype=np.float64).reshape(n, n_angles),
        descriptors={
            name: np.array([r[7][name] for r in rows], dtype=np.float64).reshape(n, -1)
            for name in ("MAP-WH", "MAP-LIS", "MAP-ST")
        },
    )
