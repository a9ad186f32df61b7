"""Hand-made legs for the walk's tests: linkages whose foot path is known in closed form."""

from __future__ import annotations

import numpy as np

from linkevo.sim.robot.leg import POSE_ANGLES, Leg


def _circle(p0, p1, r0: float, r1: float, pick) -> np.ndarray:
    """(A, 2) the intersection of circles (p0, r0) and (p1, r1) per angle that `pick` keeps."""
    d = np.linalg.norm(p1 - p0, axis=1)
    a = (r0 * r0 - r1 * r1 + d * d) / (2 * d)
    h = np.sqrt(np.maximum(r0 * r0 - a * a, 0.0))
    mid = p0 + (p1 - p0) * (a / d)[:, None]
    perp = np.stack([-(p1 - p0)[:, 1], (p1 - p0)[:, 0]], axis=1) / d[:, None]
    return pick(mid + perp * h[:, None], mid - perp * h[:, None])


def jansen_leg(scale: float = 0.15) -> Leg:
    """Theo Jansen's leg (his published link lengths, times `scale` modules), whose foot
    path has a flat bottom over about half the turn. Nodes: 0 crank pivot, 1 fixed pivot,
    2 crank tip, then the joints J, K, E, F and the foot H."""
    theta = np.arange(POSE_ANGLES) * 2 * np.pi / POSE_ANGLES
    n = len(theta)
    pivot = np.zeros((n, 2))
    fixed = np.tile([-38.0, -7.8], (n, 1))
    tip = 15.0 * np.stack([np.cos(theta), np.sin(theta)], axis=1)

    def up(c1, c2):
        return np.where((c1[:, 1] > c2[:, 1])[:, None], c1, c2)

    def down(c1, c2):
        return np.where((c1[:, 1] < c2[:, 1])[:, None], c1, c2)

    def outward(c1, c2):
        return np.where((c1[:, 0] < c2[:, 0])[:, None], c1, c2)

    j = _circle(tip, fixed, 50.0, 41.5, up)
    k = _circle(tip, fixed, 61.9, 39.3, down)
    e = _circle(fixed, j, 40.1, 55.8, outward)
    f = _circle(e, k, 39.4, 36.7, outward)
    h = _circle(f, k, 65.7, 49.0, down)
    paths = np.stack([pivot, fixed, tip, j, k, e, f, h]) * scale
    beams = [(0, 2), (2, 3), (1, 3), (1, 5), (3, 5), (2, 4), (1, 4), (5, 6), (4, 6), (4, 7), (6, 7)]
    part = [0, 1, 2, 2, 2, 3, 4, 5, 6, 6, 6]  # the triangles b-d-e and g-h-i are rigid
    return Leg(
        paths=paths,
        beams=np.array(beams, dtype=np.int64),
        part=np.array(part, dtype=np.int64),
        layer=np.array([0, 1, 0, 0, 0, 2, 1, 1, 0, 0, 0], dtype=np.int64),
        frame_nodes=np.array([0, 1], dtype=np.int64),
        foot=7,
        built=True,
    )


def crank_leg(length: float) -> Leg:
    """A bare crank of `length` modules whose tip is the foot (a wheel with one spoke)."""
    theta = np.arange(POSE_ANGLES) * 2 * np.pi / POSE_ANGLES
    tip = length * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    return Leg(
        paths=np.stack([np.zeros_like(tip), tip]),
        beams=np.array([(0, 1)], dtype=np.int64),
        part=np.array([0], dtype=np.int64),
        layer=np.array([0], dtype=np.int64),
        frame_nodes=np.array([0], dtype=np.int64),
        foot=1,
        built=True,
    )
