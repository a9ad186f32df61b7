"""Provides `pull`: a tracked linkage's document, drawings and LEGO Technic build sheet."""

from __future__ import annotations

import csv
import io
import json
import math
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.sim.linkage.linkage_doc import from_document, json_floats, to_document
from linkevo.sim.linkage.physical import TOGGLE_DEG
from linkevo.sim.robot.hexapod import UNIT_M, in_floor_order
from linkevo.sim.robot.leg import LegError, leg_from_genome
from linkevo.sim.robot.walk_rows import (
    FLOOR_FIELDS,
    FLOOR_ORDER,
    SLIDING_SHARE,
    Status,
    beyond_bound_share,
    slide_share,
)
from linkevo.sim.study import DEFAULT_ANGLES, STUDY_FITNESSES, WALKING_FITNESS
from linkevo.workers.plots.build import draw_layers, draw_path_overlay, draw_template
from linkevo.workers.plots.linkage import draw_linkage
from linkevo.workers.store import run_layout as layout
from linkevo.workers.store.artifacts import write_json_atomic, write_text_atomic
from linkevo.workers.store.linkages import SourceLinkage
from linkevo.workers.store.runs import NotFound, RunStore
from linkevo.workers.store.tables import prediction_rows

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
    "layer",
    "part",
)
SAIL_MODEL = "fitted on this SAIL trial's walks"
"""How pull and the explorer name the model that predicted a SAIL trial's cells."""


def own_modules(lengths) -> list[int]:
    """Returns each beam length rounded on its own to whole modules (at least 1)."""
    return [max(round(float(length)), 1) for length in lengths]


def build_sheet(
    document: dict,
    modules: list[int] | None = None,
    layers: list[int] | None = None,
    parts: list[str] | None = None,
) -> list[dict]:
    """Returns one row per beam: its length, its whole-module length, the error, its layer
    and the real part that builds it.

    A link of M modules lies on two holes M apart, so it needs a beam of at least M + 1
    holes. `modules` are the LEGO build's lengths (`sim.robot.lego.quantise`, one per
    beam); without them each beam is rounded on its own (at least 1 module). `layers` are
    the beams' layers (`sim.robot.layers`), 0 next to the frame, and `parts` the real
    parts their bars are built from (`beam_parts`); blank without them.
    """
    unit_mm = float(document["units"]["unit_mm"])
    if modules is None:
        modules = own_modules(beam["length"] for beam in document["beams"])
    layers = layers if layers is not None else [""] * len(modules)
    parts = parts if parts is not None else [""] * len(modules)
    rows = []
    for beam, whole, layer, part in zip(document["beams"], modules, layers, parts, strict=True):
        rows.append(
            {
                "beam": beam["id"],
                "kind": beam["kind"],
                "from": beam["start"],
                "to": beam["end"],
                "length": round(beam["length"], 3),
                "length_mm": round(beam["length"] * unit_mm, 1),
                "modules": int(whole),
                "holes": int(whole) + 1,
                "error_mm": round((whole - beam["length"]) * unit_mm, 1),
                "layer": layer,
                "part": part,
            }
        )
    return rows


def beam_parts(lego: dict, n_beams: int) -> list[str]:
    """Returns each linkage beam's real part: the part of every piece of its bar ("32525
    Technic Beam 11", pieces of a joined bar joined by " + "); blank where there is no
    build."""
    if "pieces" not in lego:
        return [""] * n_beams
    out = []
    for b in range(n_beams):
        bar = lego["bars"][b]
        out.append(
            " + ".join(f"{p['part']} {p['name']}" for p in lego["pieces"] if p["bar"] == bar)
        )
    return out


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
        lego_line(doc["lego"]),
        "",
        *(
            [shape_line(doc["shape"]), "", mounting_line(doc["mounting"]), ""]
            if "shape" in doc
            else []
        ),
        *(
            [f"Simulated walk: {walk_line(doc['simulated_walk'])}.", ""]
            if doc.get("simulated_walk")
            else []
        ),
        *(
            [f"Confirmed walk: {confirmed_line(doc['confirmed_walk'])}.", ""]
            if doc.get("confirmed_walk")
            else []
        ),
        *(
            [f"Predicted walk: {prediction_line(doc['predicted_walk'])}.", ""]
            if doc.get("predicted_walk")
            else []
        ),
        "| " + " | ".join(SHEET_COLUMNS) + " |",
        "|" + "---|" * len(SHEET_COLUMNS),
    ]
    lines += ["| " + " | ".join(str(row[c]) for c in SHEET_COLUMNS) + " |" for row in rows]
    if "pieces" in doc["lego"]:
        lines += ["", *assembly_lines(doc)]
        lines += [
            "",
            "Drawings: linkage.png (numbered as this sheet), layers.png (the beams of each "
            "layer), template.pdf (the build at 1:1 on A4 pages: print at actual size and "
            "lay the beams on it), path_overlay.png (the foot path as evolved and as built); "
            "leg.ldr (the leg in LDraw, a step per layer) and robot.mpd (the six legs as "
            "mounted), for LDView, LeoCAD, LDCad or BrickLink Studio; parts.csv and parts.xml "
            "(a BrickLink wanted list of the six legs' parts).",
        ]
    return "\n".join(lines) + "\n"


def checks_line(checks: dict) -> str:
    """Returns a linkage document's physical checks (`sim.linkage.physical`) in a sentence."""
    verdict = "buildable" if checks["buildable"] else "NOT buildable as simulated"
    turn = "turns fully" if checks["turns_fully"] else "does not turn fully"
    if checks["max_stretch"] is None:
        return f"Checks: {verdict}: it assembles at no crank angle."
    return (
        f"Checks: {verdict}: {turn}; smallest transmission angle "
        f"{checks['min_transmission_deg']:.1f} deg, {checks['toggle_passages']} toggle "
        f"passages (< {TOGGLE_DEG:g} deg); largest beam stretch {checks['max_stretch']:.3f} "
        f"modules; size {checks['width_modules']:.1f} x {checks['height_modules']:.1f} modules."
    )


def assembly_lines(doc: dict) -> list[str]:
    """Returns the joints and the parts list of a LEGO build of real parts (Markdown).

    Layer -1 is the motor's driver (just inside the crank when the crank is further out);
    a frame node's axle comes from the frame's hole; a moving joint's pin or axle spans the
    layers of the beams that meet there, fillers on the layers between.
    """
    lego = doc["lego"]
    lines = [
        f"Layers: {lego['n_layers']} (0 next to the frame). Joints, by node:",
        "",
    ]
    for joint in lego["joints"]:
        low, high = joint["layers"][0], joint["layers"][-1]
        where = "from the frame" if joint["frame"] else f"layer {low}"
        fillers = f"; fillers: {', '.join(joint['fillers'])}" if joint["fillers"] else ""
        lines.append(
            f"- node {joint['node']}: {joint['fastener']}, {where} to layer {high}{fillers}"
        )
    lines += ["", "| part | name | per leg | six legs, mounted |", "|---|---|---|---|"]
    lines += [
        f"| {row['part']} | {row['name']} | {row['per_leg']} | {row['robot']} |"
        for row in lego["parts_list"]
    ]
    lines += [
        "",
        f"Parts from the LDraw library (CC BY 4.0); the motor drives the crank through a "
        f"{lego['driver']} on its axle, pinned to the crank's second hole; joined beams are "
        "locked by two friction pins.",
    ]
    return lines


def lego_line(lego: dict) -> str:
    """Returns the LEGO build (`sim.robot.lego.quantise`) of a pulled document in one paragraph."""
    if "refused" in lego:
        return f"LEGO build: none ({lego['refused']}); the table rounds each beam on its own."
    return (
        f"LEGO build: the whole-module lengths below, chosen among {lego['roundings']} "
        f"roundings ({lego['feasible']} turn fully with rigid beams) as the one whose foot "
        f"path stays closest: it moves by {lego['mean_shift']:.2f} modules on average "
        f"(at most {lego['max_shift']:.2f}; path_overlay.png); loss {lego['original_loss']:.3f} "
        f"as evolved, {lego['loss']:.3f} as built ({lego['fitness']})."
    )


def leg_facts(leg) -> dict[str, dict]:
    """Returns a leg's shape (`sim.robot.leg.Leg.shape`: size, stroke, lift, crank share)
    and each slot's spacer layers on the study's robot with it in every slot
    (`sim.robot.mounting.robot_spacers`), as "shape" and "mounting"."""
    from linkevo.sim.robot.mounting import robot_spacers

    return {"shape": leg.shape(), "mounting": robot_spacers(leg)}


def shape_line(shape: dict) -> str:
    """Returns the leg's shape (`leg_facts`) in a sentence."""
    width, height = shape["size_cm"]
    return (
        f"Shape: the leg spans {width:.1f} x {height:.1f} cm over its turn; stroke "
        f"{shape['stroke_cm']:.1f} cm, lift {shape['lift_cm']:.1f} cm; crank share "
        f"{shape['crank_share']:.2f} (1: the foot rides the crank as a wheel's rim)."
    )


def mounting_line(spacers: dict[str, int]) -> str:
    """Returns how the legs are mounted on the study's robot (`leg_facts`) in a sentence."""
    from linkevo.sim.robot.mounting import spacers_text

    if not any(spacers.values()):
        return (
            "Mounting: every leg straight on its motor's axle (neighbouring legs never meet on "
            "the study's frame, axles 16 cm apart)."
        )
    return (
        "Mounting: neighbouring legs meet on the study's frame (axles 16 cm apart), so some "
        "sit further out on the motor's axle, on spacer layers (a Technic bush per 8 mm "
        f"layer): {spacers_text(spacers)}."
    )


def lego_build(genome, mode: str, fitness: str, n_angles: int) -> dict:
    """Returns the LEGO build of a linkage of real parts as JSON-able values, or why there is
    none (`refused`)."""
    return lego_and_parts(genome, mode, fitness, n_angles)[0]


def lego_and_parts(genome, mode: str, fitness: str, n_angles: int):
    """Returns (`lego_build`'s values, the real parts, the leg) of a linkage; the last two
    None where there is no build (`sim.robot.leg.recipe_and_leg`, the build a walk walks)."""
    from linkevo.orchestrator.parts_list import parts_rows
    from linkevo.sim.robot.leg import recipe_and_leg
    from linkevo.sim.robot.lego import QuantiseError, quantise
    from linkevo.sim.robot.mounting import robot_spacers
    from linkevo.sim.robot.parts import PartsError

    fitness = fitness if fitness in STUDY_FITNESSES else STUDY_FITNESSES[0]  # F_w: F_p
    try:
        q = quantise(genome, mode, fitness, n_angles)
        recipe, leg = recipe_and_leg(genome, mode)
    except (QuantiseError, LegError) as exc:
        return {"refused": str(exc)}, None, None
    if recipe.parts is None:
        return {"refused": recipe.note.removeprefix("walked as evolved: ")}, None, None
    parts = recipe.parts
    try:
        parts_list = parts_rows(parts, robot_spacers(leg))
    except PartsError as exc:  # a robot config's spacers past the longest axle
        return {"refused": f"mounted on the robot's spacers: {exc}"}, None, None
    first = int(np.argmax(q.motion.valid[0]))

    def named(part) -> str:
        return f"{part.name} ({part.number})"

    lego = {
        "lengths": q.lengths.tolist(),
        "layers": recipe.layer.tolist(),
        "n_layers": int(leg.piece_layer.max()) + 1,
        "roundings": q.roundings,
        "feasible": q.feasible,
        "mean_shift": q.mean_shift,
        "max_shift": q.max_shift,
        "fitness": fitness,
        "loss": q.loss,
        "original_loss": q.original_loss,
        "checks": q.checks.row(0),
        "nodes": json_floats(q.motion.positions[0, :, first]),
        "foot_path": {"x": json_floats(q.foot_x), "y": json_floats(q.foot_y)},
        "original_path": {"x": json_floats(q.original_x), "y": json_floats(q.original_y)},
        "bars": list(parts.bar_of),
        "pieces": [
            {
                "part": p.part.number,
                "name": p.part.name,
                "bar": p.bar,
                "beam": p.beam,
                "t0": p.t0,
                "t1": p.t1,
                "layer": p.layer,
            }
            for p in parts.pieces
        ],
        "joints": [
            {
                "node": j.node,
                "layers": list(j.layers),
                "frame": j.frame,
                "fastener": named(j.fastener),
                "fillers": [f"{named(part)} on layer {at:g}" for part, at in j.fillers],
            }
            for j in parts.joints
        ],
        "driver": named(parts.driver),
        "parts_list": parts_list,
    }
    return lego, parts, leg


def simulated_walks(store: RunStore, source: SourceLinkage) -> dict[str, dict]:
    """Returns the pulled cell's rows of its trial's walk map (`linkevo walkmap`, or a
    walking trial's own), per floor (distance, breaks, reason); for a walking trial's best
    linkage, its rows of the trial's walk log; {} when it was not walked."""
    if not source.run_id:
        return {}
    with tempfile.TemporaryDirectory() as tmp:
        if source.cell is not None:
            walks = store.walk_map(source.run_id, Path(tmp))
            if walks is None:
                return {}
            rows = walks[walks["cell"] == source.cell]
        elif source.fitness == WALKING_FITNESS:
            rows = _logged_walks(store, source, Path(tmp))
        else:
            return {}
    rows = rows[rows["status"] == Status.WALKED]
    order = in_floor_order(rows["floor"])
    rows = rows.sort_values("floor", key=lambda f: f.map(order.index), kind="stable")
    return {str(r["floor"]): walk_summary(r) for r in rows.to_dict("records")}


def walk_summary(row: dict) -> dict:
    """Returns a walk row as a pulled document keeps it: distance, breaks, reason, and how
    far stepping explains the distance (`sim.robot.walk_rows.beyond_bound_share`,
    `slide_share`; `slides` past `SLIDING_SHARE`)."""
    beyond, slide = beyond_bound_share(row), slide_share(row)
    return {
        "distance_cm": round(float(row["mean_distance_cm"]), 1),
        "seconds": float(row.get("seconds", 10.0)),
        "breaks": bool(row["breaks"]),
        "reason": str(row["reason"]),
        "beyond_bound": bool(beyond > 0),
        "beyond_bound_share": None if math.isnan(beyond) else round(beyond, 3),
        "slide_share": None if math.isnan(slide) else round(slide, 3),
        "slides": bool(slide > SLIDING_SHARE),
    }


def confirmed_walk(store: RunStore, source: SourceLinkage) -> dict:
    """Returns a walking trial's best linkage as confirmed on the full model
    (`best_confirmed.json`, `workers.trial_walks.confirm_best_walker`, without its genome);
    {} for anything else, or where the trial confirmed no best."""
    if not source.run_id or source.cell is not None or source.fitness != WALKING_FITNESS:
        return {}
    if layout.BEST_CONFIRMED not in store.artefact_names(source.run_id):
        return {}
    with tempfile.TemporaryDirectory() as tmp:
        path = store.download(source.run_id, layout.BEST_CONFIRMED, Path(tmp))
        confirmed = json.loads(path.read_text(encoding="utf-8"))
    genome = confirmed.pop("genome", None)
    if genome is None or not np.array_equal(genome, from_document(source.document)[0]):
        return {}
    return confirmed


def confirmed_line(confirmed: dict) -> str:
    """Returns the full model's confirmation (`confirmed_walk`) in one line."""
    floors = "; ".join(
        f"{floor} " + ("breaks" if f["full_breaks"] else f"{f['full_mean_cm']:.1f} cm")
        for floor, f in confirmed["floors"].items()
    )
    flags = [
        "the two models agree" if confirmed["agrees"] else "it DISAGREES with the lean model",
        *(["a chaotic gait (its repeats disagree widely)"] if confirmed["chaotic"] else []),
        *(["SLIDES: most of its distance is its feet sliding"] if confirmed["slides"] else []),
    ]
    return (
        f"{floors} per 10 s on the full model ({confirmed['repeats']} hand-placed starts per "
        f"floor); {'; '.join(flags)}"
    )


def _logged_walks(store: RunStore, source: SourceLinkage, tmp: Path) -> pd.DataFrame:
    """Returns a walking trial's rows (a walk map's columns) of its best linkage, from
    its walk log (`walks.parquet`); none when the log lacks it."""
    try:
        log = pd.read_parquet(store.download(source.run_id, layout.WALK_LOG, tmp))
    except NotFound:
        log = pd.DataFrame({"genome": []})
    genome = from_document(source.document)[0]
    match = [i for i, g in enumerate(log["genome"]) if np.array_equal(g, genome)]
    rows = []
    for i in match[-1:]:
        for floor in FLOOR_ORDER:
            names = {c: f"{floor}_{c}" for c in FLOOR_FIELDS}  # an older log lacks later ones
            figures = {c: log[n].iloc[i] if n in log else math.nan for c, n in names.items()}
            rows.append({"floor": floor, **figures})
    return pd.DataFrame(rows, columns=["floor", *FLOOR_FIELDS])


def predicted_walks(store: RunStore, source: SourceLinkage) -> dict[str, dict]:
    """Returns the pulled cell's rows of its trial's predicted walks (`linkevo walkmodel
    predict`, or a SAIL trial's prediction map for a cell only it holds) per floor
    (predicted distance, spread, probability of breaking, the model's run); {} when they
    were not predicted."""
    if not source.run_id or source.cell is None:
        return {}
    with tempfile.TemporaryDirectory() as tmp:
        if source.predicted:  # a SAIL trial's predicted cell: its own model's prediction
            predicted = prediction_rows(store.prediction_map(source.run_id, Path(tmp)))
            model = SAIL_MODEL
        else:
            predicted = store.walk_prediction(source.run_id, Path(tmp))
            model = store.tags(source.run_id).get(layout.PREDICTED_BY, "")
    if predicted is None:
        return {}
    rows = predicted[predicted["cell"] == source.cell]
    order = in_floor_order(rows["floor"])
    rows = rows.sort_values("floor", key=lambda f: f.map(order.index), kind="stable")
    return {
        str(r.floor): {
            "predicted_cm": round(float(r.predicted_cm), 1),
            "spread_cm": round(float(r.spread_cm), 1),
            "p_break": round(float(r.p_break), 3),
            "seconds": 10.0,
            "walk_model": model,
        }
        for r in rows.itertuples()
    }


def prediction_line(predicted: dict[str, dict]) -> str:
    """Returns the walk model's predictions in one line, marked as predicted."""
    model = next(iter(predicted.values()))["walk_model"]
    return (
        "; ".join(
            f"{floor} {p['predicted_cm']:.1f} ± {p['spread_cm']:.1f} cm in 10 s, breaks with "
            f"probability {p['p_break']:.2f}"
            for floor, p in predicted.items()
        )
        + f" (predicted by the walk model {model}, no physics)"
    )


def walk_line(walks: dict[str, dict]) -> str:
    """Returns the simulated walks in one line: the distance per floor, and breaks."""
    return (
        "; ".join(
            f"{floor} {w['distance_cm']:.1f} cm in {w['seconds']:g} s"
            + (" (beyond the level-body bound: trust it less)" if w.get("beyond_bound") else "")
            + (
                " (SLIDES: its feet slip at over half the body's speed; most of the distance "
                "is sliding, not stepping)"
                if w.get("slides")
                else ""
            )
            + (f", breaks ({w['reason']})" if w["breaks"] else "")
            for floor, w in walks.items()
        )
        + " (simulated robot: the trial's walk map or walks)"
    )


def pull(
    source: SourceLinkage,
    out: Path,
    *,
    gif: bool = False,
    walks: dict[str, dict] | None = None,
    predicted: dict[str, dict] | None = None,
    confirmed: dict | None = None,
) -> list[Path]:
    """Writes linkage.json, linkage.png, build_sheet.md and .csv, linkage.gif (with `gif`)
    and, when a LEGO build exists, path_overlay.png, layers.png (the exploded layer view)
    and template.pdf (1:1 on A4 pages) into out. `walks` (`simulated_walks`), `predicted`
    (`predicted_walks`) and `confirmed` (`confirmed_walk`) go into the document and the
    sheet."""
    out.mkdir(parents=True, exist_ok=True)
    genome, mode = from_document(source.document)
    n_angles = int(source.document.get("n_angles", DEFAULT_ANGLES))
    meta = {
        **source.document.get("meta", {}),
        "run_id": source.run_id,
        "cell": source.cell,
        "approach": source.approach,
        "fitness": source.fitness,
        "grid_id": source.grid_id,
    }
    # Written afresh from the genome, so an older document comes out complete (topology,
    # crank angles, physical checks).
    doc = to_document(genome, mode, n_angles=n_angles, meta=meta)
    doc["lego"], parts, leg = lego_and_parts(genome, mode, source.fitness, n_angles)
    if leg is None:
        try:
            leg = leg_from_genome(genome, mode)  # as evolved
        except LegError:
            leg = None  # it does not turn: no shape, no mounting
    if leg is not None:
        doc |= leg_facts(leg)
    if walks:
        doc["simulated_walk"] = walks
    if predicted:
        doc["predicted_walk"] = predicted
    if confirmed:
        doc["confirmed_walk"] = confirmed
    lego = doc["lego"]
    rows = build_sheet(
        doc, lego.get("lengths"), lego.get("layers"), beam_parts(lego, len(doc["beams"]))
    )
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=SHEET_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    paths = [out / name for name in (layout.LINKAGE_JSON, "build_sheet.md", "build_sheet.csv")]
    write_json_atomic(paths[0], doc)
    write_text_atomic(paths[1], sheet_markdown(source, doc, rows))
    write_text_atomic(paths[2], table.getvalue())
    for suffix in (".png", ".gif") if gif else (".png",):
        drawing = out / f"linkage{suffix}"
        paths.append(draw_linkage(genome, mode, drawing, n_angles=n_angles, numbered=True))
    lego = doc["lego"]
    if "lengths" in lego:
        path = lego["foot_path"], lego["original_path"]
        built = (np.array(path[0]["x"], dtype=float), np.array(path[0]["y"], dtype=float))
        evolved = (np.array(path[1]["x"], dtype=float), np.array(path[1]["y"], dtype=float))
        title = f"foot path as evolved and as built: mean shift {lego['mean_shift']:.2f} modules"
        paths.append(draw_path_overlay(evolved, built, out / "path_overlay.png", title))
        paths.append(draw_layers(doc, out / "layers.png"))
        paths.append(draw_template(doc, out / "template.pdf"))
    if parts is not None:
        paths += write_parts(parts, leg, doc, out, f"{source.approach} / {source.fitness}")
    return paths


def write_parts(parts, leg, doc: dict, out: Path, what: str) -> list[Path]:
    """Writes leg.ldr, robot.mpd (`sim.robot.ldraw`), parts.csv and parts.xml
    (`orchestrator.parts_list`) of a LEGO build of real parts into out; returns them."""
    from linkevo.orchestrator.parts_list import parts_csv, parts_xml
    from linkevo.sim.robot.hexapod import TRIPOD_OFFSETS_DEG, Frame
    from linkevo.sim.robot.ldraw import LDU, leg_ldr, robot_mpd

    frame = Frame()
    ldu_per_m = LDU / UNIT_M
    phases = {slot: math.radians(deg) for slot, deg in TRIPOD_OFFSETS_DEG.items()}
    texts = {
        "leg.ldr": leg_ldr(parts, leg, f"linkevo leg: {what}"),
        "robot.mpd": robot_mpd(
            parts,
            leg,
            phases,
            doc["mounting"],
            spacing_ldu=frame.leg_spacing * ldu_per_m,
            side_ldu=(frame.width / 2 + frame.leg_plane) * ldu_per_m,
        ),
        "parts.csv": parts_csv(doc["lego"]["parts_list"]),
        "parts.xml": parts_xml(doc["lego"]["parts_list"]),
    }
    for name, text in texts.items():
        write_text_atomic(out / name, text)
    return [out / name for name in texts]
