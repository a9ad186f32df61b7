"""Provides the JSON linkage document: export one linkage, parse one from text within
bounds, and rebuild it from a document."""

from __future__ import annotations

import json
import re

import numpy as np

from linkevo.sim.errors import LinkevoError
from linkevo.sim.linkage import kernels
from linkevo.sim.linkage.decoding import BEAM_KINDS, NODE_KINDS, LinkageBatch, check_mode, decode
from linkevo.sim.linkage.genome import MAX_BEAMS, N_GENES, N_NODES, validate_genomes
from linkevo.sim.linkage.kinematics import Motion, check_angles, simulate
from linkevo.sim.linkage.physical import physical_checks
from linkevo.sim.study import DEFAULT_ANGLES

FORMAT = "linkevo.linkage/2"
"""Version 2 adds each node's and beam's topology, so a document rebuilds without its genome."""
READABLE_FORMATS = ("linkevo.linkage/1", FORMAT)
DEFAULT_UNIT_MM = 8.0
"""One length unit is one LEGO Technic module: 8 mm hole pitch."""
MAX_DOCUMENT_BYTES = 1_000_000
"""The largest document read: one is about 10 kB (40 crank angles), 100 times that at the
most crank angles a user would ask for; anything larger is not a linkage."""
MAX_DOCUMENT_DEPTH = 16
"""The deepest nesting of brackets a document may hold (one nests 4 deep): a file nested
deeper is refused before Python's JSON parser recurses into it."""
_STRINGS = re.compile(rb'"(?:[^"\\]|\\.)*"')


class DocumentError(LinkevoError, ValueError):
    """Text or a dict that is not a readable linkage document; the message names the
    source and what is wrong."""


def check_document_size(size: int, source: str) -> None:
    """Raises DocumentError, naming `source`, when `size` bytes is too large a document."""
    if size > MAX_DOCUMENT_BYTES:
        raise DocumentError(
            f"{source}: {size:,} bytes is not a linkage document (one is about 10 kB; "
            f"allowed: at most {MAX_DOCUMENT_BYTES:,} bytes)"
        )


def parse_document(data: bytes, source: str) -> dict:
    """Returns the linkage document `data` holds (JSON), checked for size and nesting
    before it is parsed.

    Args:
        data: the file's bytes.
        source: where they came from (a path), named in errors.

    Raises:
        DocumentError: larger than `MAX_DOCUMENT_BYTES`, nested deeper than
            `MAX_DOCUMENT_DEPTH`, not UTF-8 JSON, or not a JSON object.
    """
    check_document_size(len(data), source)
    brackets = np.frombuffer(_STRINGS.sub(b'""', data), dtype=np.uint8)
    step = np.isin(brackets, (ord("["), ord("{"))).astype(np.int64) - np.isin(
        brackets, (ord("]"), ord("}"))
    )
    depth = int(np.cumsum(step).max(initial=0))
    if depth > MAX_DOCUMENT_DEPTH:
        raise DocumentError(
            f"{source}: nested {depth} levels deep, not a linkage document (allowed: at "
            f"most {MAX_DOCUMENT_DEPTH})"
        )
    try:
        doc = json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DocumentError(f"{source}: not a linkage document (not UTF-8 JSON: {exc})") from exc
    if not isinstance(doc, dict):
        raise DocumentError(
            f"{source}: not a linkage document (a JSON {type(doc).__name__}, not an object)"
        )
    return doc


def to_document(
    genome: np.ndarray,
    mode: str = "paper",
    *,
    n_angles: int = DEFAULT_ANGLES,
    unit_mm: float = DEFAULT_UNIT_MM,
    meta: dict | None = None,
) -> dict:
    """Returns the JSON-able document of one linkage.

    Args:
        genome: (56,) genes in [0, 1).
        mode: "paper" or "legacy".
        n_angles: crank angles per turn used for the foot path.
        unit_mm: millimetres per length unit (LEGO module).
        meta: free-form provenance (run id, approach, loss...) stored under "meta".

    The document holds the genome, mode, units, the nodes at crank angle 0 with how each is placed
    (`topology`: a triangle's anchors, lengths, assembly branch and backup point; an extension's
    parent beam and inverted flag), the beams (start, end, kind, length in units and mm, parent
    beam, root beam, inversions), the crank (motor, tip, length, sense and sample angles), the foot
    and its path, and the physical checks (`sim.linkage.physical`: full turn, transmission angle,
    toggles, stretch, size). `batch_from_document` rebuilds the linkage from all that without the
    genome.
    """
    genomes = validate_genomes(np.asarray(genome, dtype=np.float64).reshape(1, -1))
    batch = decode(genomes, mode)
    motion = simulate(batch, n_angles)
    foot = int(motion.foot[0])
    foot_x, foot_y = motion.positions[0, foot].T
    nodes = [
        {
            "id": j,
            "kind": NODE_KINDS[int(batch.node_kind[0, j])],
            "x": float(batch.positions0[0, j, 0]),
            "y": float(batch.positions0[0, j, 1]),
            "topology": _node_topology(batch.node_int[0, j], batch.node_float[0, j]),
        }
        for j in range(batch.node_kind.shape[1])
    ]
    beams = [
        {
            "id": b,
            "start": int(batch.beam_start[0, b]),
            "end": int(batch.beam_end[0, b]),
            "kind": BEAM_KINDS[int(batch.beam_kind[0, b])],
            "length": float(batch.beam_length[0, b]),
            "length_mm": float(batch.beam_length[0, b] * unit_mm),
            "parent": int(batch.beam_int[0, b, 3]),
            "root": int(batch.beam_int[0, b, 4]),
            "inversions": int(batch.beam_int[0, b, 5]),
        }
        for b in range(int(batch.n_beams[0]))
    ]
    return {
        "format": FORMAT,
        "mode": mode,
        "units": {"length": "LEGO module", "unit_mm": unit_mm, "angle": "rad"},
        "genome": genomes[0].tolist(),
        "n_angles": n_angles,
        "crank": {
            "motor": 0,
            "tip": 4,
            "length": beams[0]["length"],
            "sense": "counter-clockwise (x right, y up): the tip is at angle theta",
            "angles": kernels.crank_angles(n_angles, mode == "legacy").tolist(),
        },
        "tolerance": kernels.TOL,
        "checks": physical_checks(batch, motion).row(0),
        "foot": foot,
        "error": int(motion.error[0]),
        "nodes": nodes,
        "beams": beams,
        "foot_path": {
            "x": json_floats(foot_x),
            "y": json_floats(foot_y),
        },
        "meta": dict(meta or {}),
    }


def from_document(doc: dict) -> tuple[np.ndarray, str]:
    """Returns (genome (56,), mode) rebuilt from a document, after checking it.

    Raises:
        DocumentError: if the document is not a linkevo linkage document (a field missing
            or of the wrong kind), or if the beams it lists differ from those its genome
            decodes to (edited or from another version).
    """
    _check_format(doc, READABLE_FORMATS)
    mode = doc.get("mode", "paper")
    check_mode(mode)
    try:
        genome = np.asarray(doc.get("genome"), dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DocumentError(f"document genome: not {N_GENES} numbers ({exc})") from exc
    if genome.shape != (N_GENES,):
        raise DocumentError(
            f"document genome must hold {N_GENES} numbers, got shape {genome.shape}"
        )
    validate_genomes(genome.reshape(1, -1))
    beams = doc.get("beams", [])
    if not isinstance(beams, list) or not all(
        isinstance(b, dict) and isinstance(b.get("length"), int | float) for b in beams
    ):
        raise DocumentError("document beams: allowed a list of beams, each with a length")
    stored = np.array([b["length"] for b in beams], dtype=np.float64)
    batch = decode(genome.reshape(1, -1), mode)
    rebuilt = batch.beam_length[0, : int(batch.n_beams[0])]
    if stored.shape != rebuilt.shape or not np.allclose(stored, rebuilt, rtol=0, atol=1e-9):
        raise DocumentError(
            "document beams do not match its genome: edited or from another version"
        )
    return genome, mode


def json_floats(values: np.ndarray, decimals: int | None = None) -> list:
    """Returns values (any shape) as nested JSON lists of floats, None where NaN (a failed
    crank angle), rounded to `decimals` when given. `np.array(lists, dtype=float)` reads
    them back with NaN for None."""
    values = np.asarray(values, dtype=np.float64)
    if decimals is not None:
        values = np.round(values, decimals)
    return np.where(np.isfinite(values), values, None).tolist()


def batch_from_document(doc: dict) -> LinkageBatch:
    """Returns the one-linkage LinkageBatch that a version-2 document describes, built from
    its nodes and beams alone (the genome is not read).

    Raises:
        ValueError: when the document is not version 2 or a field is missing or out of range.
    """
    _check_format(doc, (FORMAT,))
    mode = doc.get("mode", "paper")
    check_mode(mode)
    nodes, beams = doc.get("nodes", []), doc.get("beams", [])
    if len(nodes) != N_NODES or not 1 <= len(beams) <= MAX_BEAMS:
        raise ValueError(
            f"a linkage document has {N_NODES} nodes and 1..{MAX_BEAMS} beams, "
            f"got {len(nodes)} and {len(beams)}"
        )
    node_int = np.full((1, N_NODES, 4), -1, np.int64)
    node_float = np.zeros((1, N_NODES, 5))
    positions0 = np.zeros((1, N_NODES, 2))
    for j, node in enumerate(nodes):
        node_int[0, j], node_float[0, j] = _node_rows(node)
        positions0[0, j] = node["x"], node["y"]
    beam_int = np.full((1, MAX_BEAMS, 6), -1, np.int64)
    beam_length = np.zeros((1, MAX_BEAMS))
    for b, beam in enumerate(beams):
        fields = (beam["start"], beam["end"], BEAM_KINDS.index(beam["kind"]), beam["parent"])
        beam_int[0, b] = (*fields, beam["root"], beam["inversions"])
        beam_length[0, b] = beam["length"]
    return LinkageBatch(
        mode=mode,
        node_int=node_int,
        node_float=node_float,
        beam_int=beam_int,
        beam_length=beam_length,
        n_beams=np.array([len(beams)], np.int64),
        positions0=positions0,
    )


def simulate_document(doc: dict, n_angles: int | None = None) -> Motion:
    """Simulates the linkage of a version-2 document over `n_angles` crank angles (default:
    the document's), from the document alone."""
    return simulate(batch_from_document(doc), check_angles(n_angles or doc["n_angles"]))


def _node_topology(ints: np.ndarray, floats: np.ndarray) -> dict:
    """How a node is placed, from its decoded rows ints (4,) and floats (5,)."""
    kind = NODE_KINDS[int(ints[0])]
    if kind == "static":
        return {"x": float(floats[0]), "y": float(floats[1])}
    if kind == "crank":
        return {"crank_length": float(floats[0])}
    if kind == "triangle":
        return {
            "anchors": [int(ints[1]), int(ints[2])],
            "lengths": [float(floats[0]), float(floats[1])],
            "branch": int(ints[3]),  # 0: the intersection right of A -> C (x right, y up)
            "backup_angle": float(floats[2]),
            "backup_offset": [float(floats[3]), float(floats[4])],
        }
    if kind == "extension":
        return {"parent_beam": int(ints[1]), "inverted": bool(ints[2]), "length": float(floats[0])}
    return {}


def _node_rows(node: dict) -> tuple[list[int], list[float]]:
    """The decoded rows (4,) int and (5,) float of a document node (inverse of _node_topology)."""
    kind = node["kind"]
    if kind not in NODE_KINDS:
        raise ValueError(f"unknown node kind {kind!r}; allowed: {', '.join(NODE_KINDS)}")
    t = node.get("topology", {})
    ints, floats = [NODE_KINDS.index(kind), -1, -1, -1], [0.0] * 5
    if kind == "static":
        floats[:2] = t["x"], t["y"]
    elif kind == "crank":
        floats[0] = t["crank_length"]
    elif kind == "triangle":
        ints[1:] = *t["anchors"], t["branch"]
        floats[:] = *t["lengths"], t["backup_angle"], *t["backup_offset"]
    elif kind == "extension":
        ints[1:3] = t["parent_beam"], int(t["inverted"])
        floats[0] = t["length"]
    return ints, floats


def _check_format(doc: object, allowed: tuple[str, ...]) -> None:
    found = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
    if found not in allowed:
        raise DocumentError(
            f"not a readable linkage document: format is {found!r}, expected {' or '.join(allowed)}"
        )
