"""Provides `pull`: a tracked linkage's document, drawings and LEGO Technic build sheet."""

from __future__ import annotations

import collections
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
from linkevo.sim.robot.hexapod import in_floor_order
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
)


def own_modules(lengths) -> list[int]:
    """Returns each beam length rounded on its own to whole modules (at least 1)."""
    return [max(round(float(length)), 1) for length in lengths]


def build_sheet(
    document: dict, modules: list[int] | None = None, layers: list[int] | None = None
) -> list[dict]:
    """Returns one row per beam: its length, the LEGO beam that builds it and the error.

    A straight Technic beam with h holes spans h - 1 modules between its end holes, so a
    link of M modules is built from a beam with M + 1 holes. `modules` are the LEGO
    build's lengths (`sim.robot.lego.quantise`, one per beam); without them each beam is
    rounded on its own (at least 1 module). `layers` are the beams' layers (`sim.robot.layers`),
    0 next to the frame; blank without them.
    """
    unit_mm = float(document["units"]["unit_mm"])
    if modules is None:
        modules = own_modules(beam["length"] for beam in document["beams"])
    layers = layers if layers is not None else [""] * len(modules)
    rows = []
    for beam, whole, layer in zip(document["beams"], modules, layers, strict=True):
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
    if "layers" in doc["lego"]:
        lines += ["", *assembly_lines(doc, rows)]
        lines += [
            "",
            "Drawings: linkage.png (numbered as this sheet), layers.png (the beams of each "
            "layer), template.pdf (the build at 1:1 on A4 pages: print at actual size and "
            "lay the beams on it), path_overlay.png (the foot path as evolved and as built).",
        ]
    lines += [
        "",
        "Extension beams continue their parent beam rigidly: build the two as one straight "
        "beam or lock them with a second pin.",
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


def assembly_lines(doc: dict, rows: list[dict]) -> list[str]:
    """Returns the pins, the motor axle and the parts list of a LEGO build (Markdown).

    Layer -1 is the frame (the motor and the static nodes' holes); a pin at a joint spans
    the layers of the beams that meet there (and the frame at a frame node).
    """
    layer = {row["beam"]: int(row["layer"]) for row in rows}
    kinds = {n["id"]: n["kind"] for n in doc["nodes"]}
    lines = [f"Layers: {doc['lego']['n_layers']} (0 next to the frame). Pins and axle:", ""]
    pins = collections.Counter()
    for node in sorted({e for b in doc["beams"] for e in (b["start"], b["end"])}):
        beams = [b["id"] for b in doc["beams"] if node in (b["start"], b["end"])]
        spans = {layer[b] for b in beams} | ({-1} if kinds[node] in ("motor", "static") else set())
        if len(spans) < 2:
            continue  # one straight beam passes through: no pin
        low, high = min(spans), max(spans)
        part = "motor axle" if kinds[node] == "motor" else f"{high - low + 1}L pin"
        where = "frame" if low == -1 else f"layer {low}"
        beam_list = ", ".join(f"b{b}" for b in beams)
        lines.append(
            f"- node {node} ({kinds[node]}): {part}, {where} to layer {high} ({beam_list})"
        )
        pins[part] += 1
    holes = collections.Counter(row["holes"] for row in rows)
    lines += [
        "",
        "Parts: "
        + ", ".join(
            [f"{n} x {h}-hole beam" for h, n in sorted(holes.items())]
            + [f"{n} x {part}" for part, n in sorted(pins.items())]
        )
        + ".",
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


def leg_facts(genome, mode: str) -> dict[str, dict]:
    """Returns the leg's shape (`sim.robot.leg.Leg.shape`: size, stroke, lift, crank share)
    and each slot's spacer layers on the study's robot with this leg in every slot
    (`sim.robot.mounting.robot_spacers`), as "shape" and "mounting"; {} for a linkage that
    does not turn."""
    from linkevo.sim.robot.leg import LegError, leg_from_genome
    from linkevo.sim.robot.mounting import robot_spacers

    try:
        leg = leg_from_genome(genome, mode)
    except LegError:
        return {}
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
    """Returns the LEGO build of a linkage as JSON-able values, or why there is none."""
    from linkevo.sim.robot.layers import layer_plan
    from linkevo.sim.robot.lego import QuantiseError, quantise

    fitness = fitness if fitness in STUDY_FITNESSES else STUDY_FITNESSES[0]  # F_w: F_p
    try:
        q = quantise(genome, mode, fitness, n_angles)
    except QuantiseError as exc:
        return {"refused": str(exc)}
    plan = layer_plan(q.batch, q.motion)
    first = int(np.argmax(q.motion.valid[0]))
    return {
        "lengths": q.lengths.tolist(),
        "layers": plan.layer.tolist(),
        "n_layers": plan.n_layers,
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
    }


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
    predict`) per floor (predicted distance, spread, probability of breaking, the model's
    run); {} when they were not predicted."""
    if not source.run_id or source.cell is None:
        return {}
    with tempfile.TemporaryDirectory() as tmp:
        predicted = store.walk_prediction(source.run_id, Path(tmp))
    if predicted is None:
        return {}
    model = store.tags(source.run_id).get(layout.PREDICTED_BY, "")
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
    doc["lego"] = lego_build(genome, mode, source.fitness, n_angles)
    doc |= leg_facts(genome, mode)
    if walks:
        doc["simulated_walk"] = walks
    if predicted:
        doc["predicted_walk"] = predicted
    if confirmed:
        doc["confirmed_walk"] = confirmed
    rows = build_sheet(doc, doc["lego"].get("lengths"), doc["lego"].get("layers"))
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
    return paths
