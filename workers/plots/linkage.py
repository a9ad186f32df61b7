"""Provides linkage drawings: a still like the paper's Fig. 1 (PNG) or one crank turn (GIF).

The LEGO build's own drawings are in `workers.plots.build`."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from linkevo.sim.linkage.decoding import decode
from linkevo.sim.linkage.genome import validate_genomes
from linkevo.sim.linkage.kinematics import simulate
from linkevo.sim.study import DEFAULT_ANGLES
from linkevo.workers.store.artifacts import atomic_path

SUFFIXES = (".png", ".gif")
LABEL_BOX = {"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none"}


def draw_linkage(
    genome: np.ndarray,
    mode: str,
    path: Path,
    *,
    n_angles: int = DEFAULT_ANGLES,
    title: str | None = None,
    numbered: bool = False,
) -> Path:
    """Writes a drawing of one linkage to `path` (.png still, .gif one crank turn).

    Shows the motor, static and moving nodes, the beams at the first crank angle (each
    frame's angle in a GIF), the crank circle and the foot path; with `numbered`, the node
    numbers and beam numbers (b0, b1, ...) of the build sheet (about 90 ms more, so the
    trials' own drawings go without). Returns `path`.
    """
    path = Path(path)
    if path.suffix.lower() not in SUFFIXES:
        raise ValueError(f"drawing file must end in .png or .gif, got {path.name!r}")
    genomes = validate_genomes(np.asarray(genome, dtype=np.float64).reshape(1, -1))
    batch = decode(genomes, mode)
    motion = simulate(batch, n_angles)
    foot = int(motion.foot[0])
    valid = np.flatnonzero(motion.valid[0])
    title = title or f"{mode} mode, foot node {foot}, error {int(motion.error[0])}"
    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".png":
            fig = _figure(batch, motion, int(valid[0]), title, numbered)
            fig.savefig(tmp, format="png", dpi=120)
        else:
            frames = [_frame_image(_figure(batch, motion, int(k), title, numbered)) for k in valid]
            frames[0].save(
                tmp, format="gif", save_all=True, append_images=frames[1:], duration=80, loop=0
            )
    return path


def _figure(batch, motion, k: int, title: str, numbered: bool):
    """Returns a matplotlib figure of linkage 0 of `batch` at sample k."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    pos = motion.positions[0, :, :, :]
    fig = Figure(figsize=(6, 6))  # no pyplot, no layout engine: fixed margins
    ax = fig.add_axes((0.12, 0.09, 0.85, 0.84))
    finite = pos[np.isfinite(pos[:, :, 0])]
    lo, hi = finite.min(axis=0) - 1.5, finite.max(axis=0) + 1.5
    crank = batch.node_float[0, 4, 0]
    ax.add_patch(Circle((0, 0), crank, fill=False, ls=":", color="0.6"))
    foot = int(motion.foot[0])
    ax.plot(*pos[foot].T, "-x", color="tab:red", ms=4, lw=1, label="foot path")
    for b in range(int(batch.n_beams[0])):
        s, e = batch.beam_start[0, b], batch.beam_end[0, b]
        ax.plot(*zip(pos[s, k], pos[e, k], strict=True), "-", color="0.25", lw=2.5, zorder=2)
        if numbered:  # beam numbers as on the build sheet
            ax.text(
                *(pos[s, k] + pos[e, k]) / 2,
                f"b{b}",
                fontsize=6,
                color="tab:green",
                ha="center",
                va="center",
                bbox=LABEL_BOX,
                zorder=6,
            )
    for j in range(pos.shape[0]) if numbered else ():  # node numbers
        if np.isfinite(pos[j, k, 0]):
            ax.annotate(
                str(j), pos[j, k], xytext=(4, 4), textcoords="offset points", fontsize=7, zorder=6
            )
    kinds = batch.node_kind[0]
    moving = kinds >= 2
    ax.scatter(*pos[moving, k].T, s=40, c="white", edgecolors="k", zorder=3, label="moving node")
    ax.scatter(*pos[kinds == 1, k].T, s=70, marker="s", c="tab:blue", zorder=3, label="static")
    ax.scatter(
        *pos[0, k], s=140, marker="o", c="tab:orange", edgecolors="k", zorder=4, label="motor"
    )
    ax.scatter(*pos[foot, k], s=90, marker="*", c="tab:red", zorder=5, label="foot")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.grid(True, lw=0.3)
    ax.set_xlabel("x (LEGO modules)")
    ax.set_ylabel("y (LEGO modules)")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="upper right", fontsize=7)
    return fig


def _frame_image(fig):
    """Returns the figure rendered as a PIL image (palette mode for GIF) and closes it."""
    from PIL import Image

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=72)
    buf.seek(0)
    return Image.open(buf).convert("P", palette=Image.Palette.ADAPTIVE)
