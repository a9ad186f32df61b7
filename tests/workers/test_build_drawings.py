"""Tests for the LEGO build's drawings: holes on whole modules, the exploded layer view,
and a template that prints at 1:1 on A4 pages covering the whole build."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from linkevo import sim
from linkevo.orchestrator.pull import lego_build
from linkevo.sim.linkage.linkage_doc import to_document
from linkevo.workers.plots.build import (
    A4_MM,
    PAGE_MARGIN_MM,
    SCALE_BAR_MM,
    draw_layers,
    draw_template,
    piece_holes,
    template_page,
    template_tiles,
)


@pytest.fixture(scope="module")
def doc():
    """A document with a LEGO build: the first random linkage the LEGO build accepts."""
    genomes = sim.random_genomes(np.random.default_rng(21), 400)
    for genome in genomes[sim.evaluate(genomes).error == 0]:
        document = to_document(genome)
        document["lego"] = lego_build(genome, "paper", "Fp", 40)
        if "lengths" in document["lego"]:
            return document
    raise AssertionError("no random linkage has a LEGO build")


def test_each_real_beam_has_its_parts_holes_one_module_apart_on_its_joints(doc):
    from linkevo.sim.robot.parts import catalogue

    holes_of = {part.number: int(part.size) for part in catalogue().beams}
    nodes = np.array(doc["lego"]["nodes"], dtype=float)
    drawn = {}
    for piece in doc["lego"]["pieces"]:
        holes = piece_holes(doc, piece)
        assert len(holes) == holes_of[piece["part"]]
        assert np.allclose(np.linalg.norm(np.diff(holes, axis=0), axis=1), 1.0, atol=1e-6)
        drawn.setdefault(piece["bar"], []).append(holes)
    for beam, bar in zip(doc["beams"], doc["lego"]["bars"], strict=True):
        holes = np.concatenate(drawn[bar])
        for node in (beam["start"], beam["end"]):  # both joints sit on a hole of its bar
            assert np.linalg.norm(holes - nodes[node], axis=1).min() < 1e-6


def test_layer_view_has_a_column_per_layer_up_to_three(doc, tmp_path):
    path = draw_layers(doc, tmp_path / "layers.png")
    n = doc["lego"]["n_layers"]
    fig_width = Image.open(path).size[0] / 120  # inches at 120 dpi: 4 per column
    assert fig_width == pytest.approx(4 * min(n, 3))


def test_template_prints_at_one_to_one_on_a4_pages_covering_the_build(doc, tmp_path):
    unit = doc["units"]["unit_mm"]
    nodes = np.array(doc["lego"]["nodes"], dtype=float) * unit
    lo, hi = nodes.min(axis=0) - 8, nodes.max(axis=0) + 8
    tiles = template_tiles(lo, hi)
    size = np.array(A4_MM) - 2 * PAGE_MARGIN_MM
    for node in nodes:  # every joint lies on some page
        assert any(((c <= node) & (node <= c + size)).all() for c in np.array(tiles))
    fig = template_page(doc, tiles[0], "page 1")
    ax = fig.axes[0]
    origin = np.array(tiles[0]) + 20
    ends = ax.transData.transform(origin + np.array([[0, 0], [SCALE_BAR_MM, 0], [0, 50]]))
    inches = np.linalg.norm(ends[1:] - ends[0], axis=1) / fig.dpi
    assert inches == pytest.approx([SCALE_BAR_MM / 25.4, 50 / 25.4], rel=1e-6)  # 1:1
    assert tuple(fig.get_size_inches() * 25.4) == pytest.approx(A4_MM)

    pdf = draw_template(doc, tmp_path / "template.pdf").read_bytes()
    boxes = re.findall(rb"/MediaBox \[ *0 0 ([\d.]+) ([\d.]+) *\]", pdf)
    assert len(boxes) == len(tiles)  # a page per tile
    assert all(float(w) == pytest.approx(595.28, abs=0.01) for w, _ in boxes)  # A4 in points
    assert all(float(h) == pytest.approx(841.89, abs=0.01) for _, h in boxes)


def test_a_path_is_drawn_with_gaps_where_its_linkage_fails():
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    from linkevo.workers.plots.repertoire import draw_paths

    angles = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    x, y = np.cos(angles), 0.5 * np.sin(angles)
    x[10:25] = np.nan  # the linkage fails over 15 of its 40 angles
    chosen = pd.DataFrame(
        {
            "foot_x": [x, np.cos(angles)],
            "foot_y": [y, np.sin(angles)],
            "row": [0, 0],
            "col": [0, 1],
            "loss": [1.0, 2.0],
        }
    )
    lines = draw_paths(Figure().add_subplot(), chosen, (1, 2), Normalize(0, 3))
    segments = lines.get_segments()
    assert len(segments) == 2  # the failing path one open run, the whole one closed
    assert len(segments[0]) == 25 and not np.allclose(segments[0][0], segments[0][-1])
    assert len(segments[1]) == 41 and np.allclose(segments[1][0], segments[1][-1])
