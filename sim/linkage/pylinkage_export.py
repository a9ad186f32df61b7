"""Provides `to_pylinkage`: a linkage document as a pylinkage `Linkage`, for users of that
library (an optional dependency: `pip install pylinkage`, or linkevo's `[pylinkage]` extra).

The mapping, node by node in decode order: the motor and the static nodes are `Ground`
points, the crank tip a `Crank` about the motor (one sample angle per step), a triangle
node an `RRRDyad` on its two anchors with its two lengths, started at its place at crank
angle 0, and an extension node a `FixedDyad` that continues its parent beam (angle pi
from the parent's other end). pylinkage keeps a triangle on the branch nearest to its last
position, where linkevo fixes the branch by orientation, and it solves beams exactly,
where linkevo accepts the spec's 0.1 tolerance: the two agree on linkages that turn fully
with rigid beams and pass no toggle position (`sim.linkage.physical`'s buildable ones).
"""

from __future__ import annotations

import math


def to_pylinkage(doc: dict):
    """Returns the pylinkage `Linkage` of a version-2 linkage document (`sim.linkage.linkage_doc`).

    Its `components` hold one component per node, in node order, and its crank turns by
    one of the document's sample angles per step: `linkage.step(iterations=10 * A,
    dt=0.1)` yields every node's (x, y) ten times per sample, starting a tenth of a
    sample after angle 0. Step that finely: pylinkage keeps each triangle on the solution
    nearest its last position, and a whole sample can carry a joint nearer to the other
    branch.

    Raises:
        ImportError: pylinkage is not installed (the message says how to install it).
        ValueError: a node kind pylinkage has no counterpart for.
    """
    try:
        import pylinkage as pl
    except ImportError as exc:
        raise ImportError(
            "to_pylinkage needs pylinkage: pip install pylinkage (or linkevo[pylinkage])"
        ) from exc
    angles = doc["crank"]["angles"]
    step = angles[1] - angles[0] if len(angles) > 1 else 2 * math.pi
    beams = doc["beams"]
    parts: dict[int, object] = {}
    for node in doc["nodes"]:
        j, kind, t = node["id"], node["kind"], node.get("topology", {})
        name = f"node {j} ({kind})"
        if kind in ("motor", "static"):
            parts[j] = pl.Ground(node["x"], node["y"], name=name)
        elif kind == "crank":
            parts[j] = pl.Crank(
                anchor=parts[doc["crank"]["motor"]],
                radius=t["crank_length"],
                angular_velocity=step,
                initial_angle=angles[0],
                name=name,
            )
        elif kind == "triangle":
            a, c = t["anchors"]
            parts[j] = pl.RRRDyad(
                _output(parts[a]),
                _output(parts[c]),
                t["lengths"][0],
                t["lengths"][1],
                x=node["x"],
                y=node["y"],
                name=name,
            )
        elif kind == "extension":
            parent = beams[t["parent_beam"]]
            start, other = parent["end"], parent["start"]
            if t["inverted"]:
                start, other = other, start
            parts[j] = pl.FixedDyad(
                _output(parts[start]), _output(parts[other]), t["length"], math.pi, name=name
            )
        else:
            raise ValueError(f"node {j}: kind {kind!r} has no pylinkage counterpart")
    return pl.Linkage(list(parts.values()), name=doc.get("meta", {}).get("trial_key", "linkevo"))


def _output(component):
    """The point of a component other dyads attach to (a crank's tip, else itself)."""
    return getattr(component, "output", component)
