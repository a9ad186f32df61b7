"""Provides `pull`: a tracked linkage's document, drawings and LEGO Technic build sheet."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from sim.linkage_doc import from_document, to_document
from sim.physical import TOGGLE_DEG
from workers.artifacts import write_json_atomic, write_text_atomic
from workers.drawing import draw_linkage
from workers.linkages import SourceLinkage

SHEET_COLUMNS = (
    "beam",
    "kind",
    "from",
    "to",
    "length",
    "length_mm",
    "modules",
    "holes",
    "error_mm",
)


def build_sheet(document: dict) -> list[dict]:
    """Returns one row per beam: its length, the nearest LEGO beam and the rounding error.

    A straight Technic beam with h holes spans h - 1 modules between its end holes, so a
    link of length L modules is built from a beam with round(L) + 1 holes (at least 2).
    """
    unit_mm = float(document["units"]["unit_mm"])
    rows = []
    for beam in document["beams"]:
        modules = max(round(beam["length"]), 1)
        rows.append(
            {
                "beam": beam["id"],
                "kind": beam["kind"],
                "from": beam["start"],
                "to": beam["end"],
                "length": round(beam["length"], 3),
                "length_mm": round(beam["length"] * unit_mm, 1),
                "modules": modules,
                "holes": modules + 1,
                "error_mm": round((modules - beam["length"]) * unit_mm, 1),
            }
        )
    return rows


def sheet_markdown(source: SourceLinkage, doc: dict, rows: list[dict]) -> str:
    """Returns the build sheet of a linkage document as a Markdown page."""
    where = source.run_id + (f", cell {source.cell}" if source.cell is not None else " (best)")
    statics = [n for n in doc["nodes"] if n["kind"] == "static"]
    lines = [
        f"# Build sheet: {source.approach} / {source.fitness}",
        "",
        f"Source run {where}; mode {doc['mode']}; 1 module = {doc['units']['unit_mm']} mm.",
        f"Crank: {doc['crank']['length']:.3f} modules. Foot: node {doc['foot']}.",
        "",
        "Frame holes (static nodes, modules from the motor axle): "
        + ", ".join(f"node {n['id']} at ({n['x']:.0f}, {n['y']:.0f})" for n in statics),
        "",
        checks_line(doc["checks"]),
        "",
        "| " + " | ".join(SHEET_COLUMNS) + " |",
        "|" + "---|" * len(SHEET_COLUMNS),
    ]
    lines += ["| " + " | ".join(str(row[c]) for c in SHEET_COLUMNS) + " |" for row in rows]
    lines += [
        "",
        "Extension beams continue their parent beam rigidly: build the two as one straight "
        "beam or lock them with a second pin.",
    ]
    return "\n".join(lines) + "\n"


def checks_line(checks: dict) -> str:
    """Returns the physical checks of a linkage document (`sim.physical`) in one sentence."""
    verdict = "buildable" if checks["buildable"] else "NOT buildable as simulated"
    turn = "turns fully" if checks["turns_fully"] else "does not turn fully"
    return (
        f"Checks: {verdict}: {turn}; smallest transmission angle "
        f"{checks['min_transmission_deg']:.1f} deg, {checks['toggle_passages']} toggle "
        f"passages (< {TOGGLE_DEG:g} deg); largest beam stretch {checks['max_stretch']:.3f} "
        f"modules; size {checks['width_modules']:.1f} x {checks['height_modules']:.1f} modules."
    )


def pull(source: SourceLinkage, out: Path, *, gif: bool = False) -> list[Path]:
    """Writes linkage.json, linkage.png, build_sheet.md and .csv (and linkage.gif) into out."""
    out.mkdir(parents=True, exist_ok=True)
    genome, mode = from_document(source.document)
    n_angles = int(source.document.get("n_angles", 40))
    meta = {
        **source.document.get("meta", {}),
        "run_id": source.run_id,
        "cell": source.cell,
        "approach": source.approach,
        "fitness": source.fitness,
    }
    # Written afresh from the genome, so an older document comes out complete (topology,
    # crank angles, physical checks).
    doc = to_document(genome, mode, n_angles=n_angles, meta=meta)
    rows = build_sheet(doc)
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=SHEET_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    paths = [out / name for name in ("linkage.json", "build_sheet.md", "build_sheet.csv")]
    write_json_atomic(paths[0], doc)
    write_text_atomic(paths[1], sheet_markdown(source, doc, rows))
    write_text_atomic(paths[2], table.getvalue())
    for suffix in (".png", ".gif") if gif else (".png",):
        paths.append(draw_linkage(genome, mode, out / f"linkage{suffix}", n_angles=n_angles))
    return paths
