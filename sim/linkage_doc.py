"""Provides the JSON linkage document: export one linkage, and rebuild it from a document."""

from __future__ import annotations

import math

import numpy as np

from sim.decode import BEAM_KINDS, NODE_KINDS, check_mode, decode
from sim.genome import N_GENES, validate_genomes
from sim.kinematics import DEFAULT_ANGLES, simulate

FORMAT = "linkevo.linkage/1"
DEFAULT_UNIT_MM = 8.0
"""One length unit is one LEGO Technic module: 8 mm hole pitch."""


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

    The document holds the genome, mode, units, the nodes at crank angle 0, the beams
    (start, end, length in units and mm, kind), the crank, the foot and its path.
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
        }
        for b in range(int(batch.n_beams[0]))
    ]
    return {
        "format": FORMAT,
        "mode": mode,
        "units": {"length": "LEGO module", "unit_mm": unit_mm, "angle": "rad"},
        "genome": genomes[0].tolist(),
        "n_angles": n_angles,
        "crank": {"motor": 0, "tip": 4, "length": beams[0]["length"]},
        "foot": foot,
        "error": int(motion.error[0]),
        "nodes": nodes,
        "beams": beams,
        "foot_path": {
            "x": [None if math.isnan(v) else float(v) for v in foot_x],
            "y": [None if math.isnan(v) else float(v) for v in foot_y],
        },
        "meta": dict(meta or {}),
    }


def from_document(doc: dict) -> tuple[np.ndarray, str]:
    """Returns (genome (56,), mode) rebuilt from a document, after checking it.

    Raises:
        ValueError: if the document is not a linkevo linkage document, or if the beams it
            lists differ from those its genome decodes to (edited or from another version).
    """
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        found = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise ValueError(f"not a linkage document: format is {found!r}, expected {FORMAT!r}")
    mode = doc.get("mode", "paper")
    check_mode(mode)
    genome = np.asarray(doc.get("genome"), dtype=np.float64)
    if genome.shape != (N_GENES,):
        raise ValueError(f"document genome must hold {N_GENES} numbers, got shape {genome.shape}")
    validate_genomes(genome.reshape(1, -1))
    stored = np.array([b["length"] for b in doc.get("beams", [])], dtype=np.float64)
    batch = decode(genome.reshape(1, -1), mode)
    rebuilt = batch.beam_length[0, : int(batch.n_beams[0])]
    if stored.shape != rebuilt.shape or not np.allclose(stored, rebuilt, rtol=0, atol=1e-9):
        raise ValueError("document beams do not match its genome: edited or from another version")
    return genome, mode
