"""Provides the LEGO build's drawings: the foot path as evolved and as built (PNG), the
exploded layer view (PNG) and the 1:1 printable template (PDF, tiled on A4 pages).

Beams are drawn as the real Technic beams of the build (`sim.robot.parts`): 7.2 mm wide
with rounded ends and a 4.8 mm hole at every module (8 mm pitch), each as long as its part,
overhang past a joint and the overlap of joined beams included.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from linkevo.workers.plots.linkage import LABEL_BOX
from linkevo.workers.store.artifacts import atomic_path

BEAM_HALF_WIDTH = 0.45
"""Half a Technic beam's width, modules (7.2 mm / 2 at 8 mm per module)."""
HOLE_RADIUS = 0.3
"""A Technic hole's radius, modules (4.8 mm / 2)."""
A4_MM = (210.0, 297.0)
PAGE_MARGIN_MM = 10.0
SCALE_BAR_MM = 50.0
LAYER_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink")


def draw_path_overlay(
    original: tuple[np.ndarray, np.ndarray],
    built: tuple[np.ndarray, np.ndarray],
    path: Path,
    title: str,
) -> Path:
    """Writes a PNG of a linkage's foot path (x (A,), y (A,)) over its LEGO build's."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 4.5))
    ax = fig.add_axes((0.12, 0.12, 0.85, 0.8))
    ax.plot(*original, "-o", color="0.5", ms=3, lw=1, label="simulated (evolved lengths)")
    ax.plot(*built, "-x", color="tab:red", ms=4, lw=1.2, label="LEGO build (whole modules)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, lw=0.3)
    ax.set_xlabel("x (LEGO modules)")
    ax.set_ylabel("y (LEGO modules)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    return Path(path)


def beam_outline(start: np.ndarray, end: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Returns the outline (K, 2) of a Technic beam from `start` to `end` ((2,) each, in
    modules), times `scale` (8.0 gives millimetres): two half circles joined by straight
    sides."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    heading = math.atan2(*(end - start)[::-1])
    half = np.linspace(-math.pi / 2, math.pi / 2, 13)
    cap_end = end + BEAM_HALF_WIDTH * np.stack([np.cos(heading + half), np.sin(heading + half)], 1)
    back = heading + math.pi + half
    cap_start = start + BEAM_HALF_WIDTH * np.stack([np.cos(back), np.sin(back)], 1)
    return np.concatenate([cap_end, cap_start]) * scale


def piece_holes(doc: dict, piece: dict) -> np.ndarray:
    """Returns the holes (H, 2) of one real beam of a document's LEGO build
    (`doc["lego"]["pieces"]`), modules: holes `t0` to `t1` along its linkage beam, counted
    from the beam's start node, so the part's overhang and a joined beam's overlap show."""
    lego = doc["lego"]
    nodes = np.array(lego["nodes"], dtype=float)
    beam = doc["beams"][piece["beam"]]
    start = nodes[beam["start"]]
    along = (nodes[beam["end"]] - start) / lego["lengths"][piece["beam"]]
    t = np.arange(piece["t0"], piece["t1"] + 1, dtype=float)[:, None]
    return start + t * along


def _draw_build(ax, doc: dict, scale: float, only_layer: int | None = None) -> None:
    """Draws a document's LEGO build (`doc["lego"]`) on `ax` at `scale` per module: every
    real beam on its layer's colour (with `only_layer`, that layer's beams and the others
    faint), holes, beam and node numbers, the frame's holes and the motor axle."""
    from matplotlib.patches import Circle, Polygon

    lego = doc["lego"]
    nodes = np.array(lego["nodes"], dtype=float)  # NaN where None
    for piece in lego["pieces"]:
        holes = piece_holes(doc, piece)
        a, b, layer = holes[0], holes[-1], piece["layer"]
        if only_layer is not None and layer != only_layer:
            ax.plot(*np.stack([a, b]).T * scale, "-", color="0.85", lw=1, zorder=1)
            continue
        colour = LAYER_COLOURS[layer % len(LAYER_COLOURS)]
        ax.add_patch(
            Polygon(
                beam_outline(a, b, scale),
                closed=True,
                fc=colour,
                ec="k",
                lw=0.4,
                alpha=0.45,
                zorder=2 + layer,
            )
        )
        for hole in holes:
            ax.add_patch(
                Circle(hole * scale, HOLE_RADIUS * scale, fc="white", ec="k", lw=0.3, zorder=20)
            )
        ax.text(
            *(a + b) / 2 * scale,
            f"b{piece['beam']} L{layer} {piece['part']}",
            fontsize=5,
            ha="center",
            va="center",
            zorder=30,
            bbox=LABEL_BOX,
        )
    for node in doc["nodes"]:
        where = nodes[node["id"]] * scale
        if not np.isfinite(where).all():
            continue
        if node["kind"] in ("motor", "static"):
            marker = "+" if node["kind"] == "motor" else "s"
            ax.plot(*where, marker, color="k", ms=8 if marker == "+" else 4, mew=1.2, zorder=31)
        ax.annotate(
            str(node["id"]), where, xytext=(3, 3), textcoords="offset points", fontsize=5, zorder=31
        )


def _bounds(doc: dict) -> tuple[np.ndarray, np.ndarray]:
    """Returns the (2,) lower and upper corners of a build's drawing, modules."""
    nodes = np.array(doc["lego"]["nodes"], dtype=float)  # NaN where None
    holes = [piece_holes(doc, piece)[[0, -1]] for piece in doc["lego"]["pieces"]]
    points = np.concatenate([nodes[np.isfinite(nodes).all(axis=1)], *holes])
    pad = BEAM_HALF_WIDTH + 0.5
    return points.min(axis=0) - pad, points.max(axis=0) + pad


def draw_layers(doc: dict, path: Path) -> Path:
    """Writes the exploded layer view of a document's LEGO build (PNG): one panel per
    layer, 0 (next to the frame) first, with that layer's beams and the rest faint."""
    from matplotlib.figure import Figure

    n_layers = int(doc["lego"]["n_layers"])
    columns = min(n_layers, 3)
    rows = math.ceil(n_layers / columns)
    lo, hi = _bounds(doc)
    panel = min(max(4 * (hi[1] - lo[1]) / (hi[0] - lo[0]), 2.0), 6.0) + 0.4  # inches high
    fig = Figure(figsize=(4 * columns, panel * rows + 0.4), layout="constrained")
    for layer in range(n_layers):
        ax = fig.add_subplot(rows, columns, layer + 1)
        _draw_build(ax, doc, 1.0, only_layer=layer)
        beams = [f"b{p['beam']}" for p in doc["lego"]["pieces"] if p["layer"] == layer]
        ax.set_title(f"layer {layer}: {', '.join(beams)}", fontsize=8)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.tick_params(labelsize=6)
        ax.grid(True, lw=0.2)
    fig.suptitle("LEGO build by layer (+ motor axle, squares frame holes; modules)", fontsize=9)
    with atomic_path(Path(path)) as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    return Path(path)


def template_tiles(lo_mm: np.ndarray, hi_mm: np.ndarray) -> list[tuple[float, float]]:
    """Returns the lower-left corners (mm) of the A4 tiles that cover a drawing spanning
    `lo_mm` to `hi_mm` ((2,) each), row by row from the top, each tile the page less its
    margins."""
    width, height = (np.array(A4_MM) - 2 * PAGE_MARGIN_MM).tolist()
    columns = max(math.ceil((hi_mm[0] - lo_mm[0]) / width), 1)
    rows = max(math.ceil((hi_mm[1] - lo_mm[1]) / height), 1)
    top = lo_mm[1] + rows * height
    return [
        (lo_mm[0] + c * width, top - (r + 1) * height) for r in range(rows) for c in range(columns)
    ]


def template_page(doc: dict, corner: tuple[float, float], label: str):
    """Returns one A4 page (a matplotlib figure) of the 1:1 template: the build in
    millimetres, the tile whose lower-left corner is `corner`, a 50 mm scale bar."""
    from matplotlib.figure import Figure

    unit = float(doc["units"]["unit_mm"])
    page_w, page_h = A4_MM
    fig = Figure(figsize=(page_w / 25.4, page_h / 25.4))
    m = PAGE_MARGIN_MM
    ax = fig.add_axes((m / page_w, m / page_h, 1 - 2 * m / page_w, 1 - 2 * m / page_h))
    _draw_build(ax, doc, unit)
    ax.set_xlim(corner[0], corner[0] + page_w - 2 * m)
    ax.set_ylim(corner[1], corner[1] + page_h - 2 * m)
    ax.set_axis_off()
    x, y = corner[0] + 5, corner[1] + 5
    ax.plot([x, x + SCALE_BAR_MM], [y, y], "-", color="k", lw=1.5)
    ax.text(x, y + 2, f"{SCALE_BAR_MM:g} mm: print at 100 % (actual size)", fontsize=6)
    fig.text(0.5, 1 - 0.6 * m / page_h, label, ha="center", va="center", fontsize=7)
    return fig


def draw_template(doc: dict, path: Path) -> Path:
    """Writes the 1:1 template of a document's LEGO build as a PDF of A4 pages (one page
    per tile, `template_tiles`): each beam at its place at the first assembled crank
    angle, its holes, layer and number; the frame's holes and the motor axle."""
    from matplotlib.backends.backend_pdf import PdfPages

    lo, hi = _bounds(doc)
    unit = float(doc["units"]["unit_mm"])
    tiles = template_tiles(lo * unit, hi * unit)
    with atomic_path(Path(path)) as tmp, PdfPages(tmp) as pdf:
        for k, corner in enumerate(tiles):
            label = f"linkevo LEGO template, 1:1, page {k + 1} of {len(tiles)}"
            pdf.savefig(template_page(doc, corner, label))
    return Path(path)
