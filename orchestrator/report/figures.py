"""Provides the report's figures: best-loss boxes, repertoire maps, path maps, convergence."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from matplotlib.ticker import FuncFormatter, MaxNLocator

from linkevo.orchestrator.report.load import GridData, read_archive, read_archives
from linkevo.sim.linkage.descriptors import DESCRIPTOR_SPACES, DescriptorSpace
from linkevo.sim.study import LEARNED, is_map_elites, label
from linkevo.workers.plots.repertoire import (
    DOWNSAMPLED,
    LOSS_CMAP,
    LOSS_LABEL,
    STRIP_PATHS,
    draw_paths,
    loss_norm,
    select_paths,
)
from linkevo.workers.store.tables import bin_columns, fold_bins, space_of

CONVERGENCE_METRICS: tuple[tuple[str, str], ...] = (
    ("best_loss", "best loss"),
    ("coverage", "coverage, own grid"),
    ("qd_score", "QD-score, own grid"),
    ("common_coverage", "coverage, common grid"),
    ("common_qd_score", "QD-score, common grid"),
)
LOWER_IS_BETTER = frozenset({"best_loss"})
"""The convergence measures where lower is better (the others: higher)."""
MAX_DIMS = 4
"""The most descriptor dimensions a map has (bin_0..bin_3)."""
PAGE_WIDTH_IN = 6.5
"""A report figure is at most this wide (a letter or A4 page's text width), so it is
shown at its own size or larger on a page and in the HTML report."""
MIN_FONT_PT = 7.0
"""The smallest text on a report figure at page width."""
REPORT_RC = {
    "font.size": MIN_FONT_PT,
    "axes.titlesize": 8.0,
    "axes.labelsize": MIN_FONT_PT,
    "xtick.labelsize": MIN_FONT_PT,
    "ytick.labelsize": MIN_FONT_PT,
    "legend.fontsize": MIN_FONT_PT,
    "figure.titlesize": 8.0,
}
"""matplotlib settings every report figure is drawn under (`build.report_figures`)."""


def study_title(grid: GridData, fitness: str | None = None) -> str:
    """Returns the line every figure carries: mode, budget, trials (and the fitness when
    the figure shows one), so a figure read on its own says which study it is."""
    cfg = grid.config
    counts = grid.trials.groupby(["approach", "fitness"]).size()
    trials = int(counts.max()) if len(counts) else 0
    first = [f"{cfg.get('mode', '?')} mode", f"grid {grid.grid_id}"]
    if fitness is not None:
        first.insert(0, label(fitness))
    budget = f"{int(cfg.get('evaluations', 0)):,} evaluations per trial, {trials} trials per cell"
    return " · ".join(first) + "\n" + budget


def thousands(ax, axis: str = "x") -> None:
    """Writes an axis's tick labels in thousands ("200k", "1.5k"), which stay apart at any
    width and never repeat (a tick between thousands keeps its decimal)."""
    formatter = FuncFormatter(
        lambda v, _: f"{v / 1000:,.{0 if v % 1000 == 0 else 1}f}k" if v else "0"
    )
    (ax.xaxis if axis == "x" else ax.yaxis).set_major_formatter(formatter)


@dataclass(frozen=True)
class ReportFigure:
    """One figure of the report.

    Attributes:
        name: file stem, e.g. "best_loss" (written as best_loss.png and best_loss.pdf).
        title: heading in the HTML report.
        caption: what the figure shows and how it was made.
        figure: the matplotlib figure.
    """

    name: str
    title: str
    caption: str
    figure: Figure


def merged_repertoire(grid: GridData, approach: str, fitness: str) -> pd.DataFrame:
    """Returns the best loss per cell over all finished trials of one MAP-Elites cell.

    Returns:
        Columns bin_0..bin_{D-1}, loss; one row per filled cell.
    """
    trials = grid.finished()
    paths = trials.archive[(trials.approach == approach) & (trials.fitness == fitness)].dropna()
    if paths.empty:
        return pd.DataFrame(columns=["loss"])
    columns = ["cell", "loss", *(f"bin_{d}" for d in range(MAX_DIMS))]
    frames = [
        frame[(frame.cell >= 0) & np.isfinite(frame.loss)].drop(columns="cell")
        for frame in read_archives(paths, columns)
    ]
    merged = pd.concat(frames, ignore_index=True)
    bins = bin_columns(merged.columns)
    return merged.groupby(bins, as_index=False)["loss"].min()


def _trial_count(grid: GridData, approach: str, fitness: str) -> str:
    """Returns "k of n trials" for a cell, naming failed and missing ones."""
    cell = grid.trials[(grid.trials.approach == approach) & (grid.trials.fitness == fitness)]
    done = int(((cell.status == "FINISHED") & cell.best_loss.notna()).sum())
    text = f"{done} of {len(cell)} trials"
    failed = int((cell.status != "FINISHED").sum())
    return text if failed == 0 else f"{text}; {failed} failed or missing"


def best_loss_figure(grid: GridData) -> ReportFigure:
    """Returns box plots of the best loss per trial, one panel per fitness."""
    fitnesses, approaches = grid.fitnesses(), grid.approaches()
    fig = Figure(figsize=(PAGE_WIDTH_IN, 2.9 * len(fitnesses) + 0.4), layout="constrained")
    axes = fig.subplots(len(fitnesses), 1, squeeze=False)[:, 0]
    rng = np.random.default_rng(0)
    done = grid.finished()
    for ax, fitness in zip(axes, fitnesses, strict=True):
        data = [
            done.best_loss[(done.approach == a) & (done.fitness == fitness)].to_numpy()
            for a in approaches
        ]
        positions = np.arange(1, len(approaches) + 1)
        filled = [i for i, d in enumerate(data) if d.size]
        if filled:
            ax.boxplot(
                [data[i] for i in filled],
                positions=positions[filled],
                widths=0.6,
                showfliers=False,
                medianprops={"color": "black"},
            )
        for i, (pos, values) in enumerate(zip(positions, data, strict=True)):
            jitter = rng.uniform(-0.15, 0.15, values.size)
            ax.scatter(pos + jitter, values, s=12, alpha=0.7, zorder=3, color=f"C{i}")
        ticks = []
        for approach, values in zip(approaches, data, strict=True):
            cell = grid.trials[
                (grid.trials.approach == approach) & (grid.trials.fitness == fitness)
            ]
            lost = int(len(cell) - values.size)
            ticks.append(
                f"{label(approach)}\nn={values.size}" + (f"\n{lost} not finished" if lost else "")
            )
        ax.set_xticks(positions, ticks)
        ax.set_xlim(0.4, len(approaches) + 0.6)
        ax.set_title(label(fitness))
        ax.set_ylabel("best loss (lower is better)")
        ax.grid(axis="y", alpha=0.3)
    fig.suptitle(study_title(grid))
    return ReportFigure(
        name="best_loss",
        title="Best loss per trial",
        caption=(
            "Distribution of the best loss found in each finished trial, per approach and "
            "fitness (lower is better; box: quartiles, whiskers: 1.5 IQR, points: trials). n "
            "counts finished "
            "trials; failed, killed or missing trials are named under the approach."
        ),
        figure=fig,
    )


def _nested_axis(ax, axis: str, space: DescriptorSpace, outer: int, inner: int) -> None:
    """Labels one axis of a folded 4-D map: outer bins as ticks, inner in the label."""
    r = space.resolution
    centres = np.arange(r) * r + (r - 1) / 2
    set_ticks = ax.set_xticks if axis == "x" else ax.set_yticks
    set_ticks(centres, [str(i) for i in range(r)])
    edges = np.arange(1, r) * r - 0.5
    lines = ax.vlines if axis == "x" else ax.hlines
    lines(edges, -0.5, r * r - 0.5, color="0.8", lw=0.4)
    # two lines: a label as long as the axis would run into its neighbours at page width
    text = f"{space.names[outer]} (outer bins)\n› {space.names[inner]} (inner, 0–{r - 1})"
    (ax.set_xlabel if axis == "x" else ax.set_ylabel)(text)


def _folded_map(grid: GridData, approach: str, fitness: str) -> tuple[np.ndarray, DescriptorSpace]:
    """Returns (image (side, side) of best loss per cell, NaN where empty; the space)."""
    merged = merged_repertoire(grid, approach, fitness)
    bins = bin_columns(merged.columns)
    space = space_of(approach, len(bins) or DESCRIPTOR_SPACES[approach].dims)
    side = space.resolution if space.dims == 2 else space.resolution**2
    image = np.full((side, side), np.nan)
    if len(merged):
        rows, cols, _ = fold_bins(merged[bins].to_numpy(), space.resolution)
        image[rows, cols] = merged.loss.to_numpy()
    return image, space


def repertoire_maps_figure(grid: GridData) -> ReportFigure | None:
    """Returns the best loss per cell over all trials, per MAP-Elites approach and fitness.

    None when the grid holds no MAP-Elites approach.
    """
    approaches = [a for a in grid.approaches() if is_map_elites(a)]
    if not approaches:
        return None
    fitnesses = grid.fitnesses()
    fig = Figure(figsize=(PAGE_WIDTH_IN, 2.9 * len(approaches) + 0.6), layout="constrained")
    axes = fig.subplots(len(approaches), len(fitnesses), squeeze=False)
    done = grid.finished()
    for col, fitness in enumerate(fitnesses):
        images = [_folded_map(grid, approach, fitness) for approach in approaches]
        finite = np.concatenate([image[np.isfinite(image)] for image, _ in images])
        norm = loss_norm(finite)
        for row, (approach, (image, space)) in enumerate(zip(approaches, images, strict=True)):
            ax = axes[row, col]
            shown = ax.imshow(
                np.ma.masked_invalid(image),
                origin="lower",
                cmap=LOSS_CMAP,
                norm=norm,
                interpolation="nearest",
                aspect="equal",
            )
            own = done.coverage[(done.approach == approach) & (done.fitness == fitness)]
            grids = "learned grids" if approach in LEARNED else "trials"
            cells = (
                f"POOLED over {own.size} {grids},\n{int(np.isfinite(image).sum()):,} cells "
                f"filled; each trial {own.median():.2f} of its own"
                if own.size
                else "no finished trial"
            )
            ax.set_title(
                f"{label(approach)}, {label(fitness)}: {cells}\n"
                f"{_trial_count(grid, approach, fitness)}"
            )
            if space.dims == 4:
                _nested_axis(ax, "y", space, 0, 2)
                _nested_axis(ax, "x", space, 1, 3)
            else:
                ax.set_ylabel(f"{space.names[0]} (bin)")
                ax.set_xlabel(f"{space.names[1]} (bin)")
        fig.colorbar(
            shown,
            ax=axes[:, col].tolist(),
            shrink=0.6,
            label=f"best {LOSS_LABEL}",
            extend="max",
            location="bottom",
        )
    fig.suptitle(study_title(grid))
    return ReportFigure(
        name="repertoire_maps",
        title="Repertoire maps",
        caption=(
            "Best loss found in each cell over all finished trials of each MAP-Elites "
            "approach (lower is better); blank cells were never filled. Every panel pools "
            "its trials (POOLED) and gives a trial's median coverage of its own grid beside "
            "the pooled count. 4-D maps are folded to 100 × 100: "
            "row = b0·10 + b2, column = b1·10 + b3, so tick labels give the outer bins and "
            "each 10 × 10 block spans the inner pair. MAP-AU learns its grid anew in every "
            "trial, so its pooled map lays differently defined cells over each other."
        ),
        figure=fig,
    )


def _best_trial(grid: GridData, approach: str, fitness: str) -> pd.Series | None:
    """Returns the finished trial with the lowest best loss of a cell, or None."""
    done = grid.finished()
    cell = done[(done.approach == approach) & (done.fitness == fitness) & done.archive.notna()]
    if cell.empty:
        return None
    return cell.loc[cell.best_loss.idxmin()]


def path_maps_figure(grid: GridData, fitness: str) -> ReportFigure | None:
    """Returns example paths of every approach for one fitness (None when none finished).

    Each approach shows its best trial (lowest best loss): MAP-Elites as a 5 × 5 map on
    the top row, NSGA-II and EA as strips of 5 paths below. Paths are scaled to fit their
    cell; the number in the corner is the path's size (the larger of its width and height,
    in units); one colour scale (the single-objective loss) serves the whole figure.
    """
    panels = []
    for approach in grid.approaches():
        trial = _best_trial(grid, approach, fitness)
        if trial is None:
            continue
        columns = ["cell", "loss", "loss_0", "loss_1", "foot_x", "foot_y"]
        columns += [f"bin_{d}" for d in range(MAX_DIMS)]
        chosen = select_paths(read_archive(trial.archive, columns), approach)
        if len(chosen):
            panels.append((approach, trial, chosen))
    if not panels:
        return None
    maps = [p for p in panels if is_map_elites(p[0])]
    strips = [p for p in panels if not is_map_elites(p[0])]
    ncols = min(2, len(panels))
    groups = [maps[i : i + ncols] for i in range(0, len(maps), ncols)]
    groups += [strips[i : i + ncols] for i in range(0, len(strips), ncols)]
    heights = [5.0 if is_map_elites(g[0][0]) else 1.4 for g in groups]
    width = PAGE_WIDTH_IN / ncols - 0.4  # a panel's side, beside its colour bar's share
    fig = Figure(
        figsize=(PAGE_WIDTH_IN, width / 5.0 * sum(heights) + 0.4 * len(groups) + 0.9),
        layout="constrained",
    )
    axes = fig.subplots(len(groups), ncols, squeeze=False, height_ratios=heights)
    losses = np.concatenate([c.loss.to_numpy(dtype=float) for _, _, c in panels])
    norm = loss_norm(losses)
    lines = None
    for row, group in enumerate(groups):
        for col in range(ncols):
            ax = axes[row, col]
            if col >= len(group):
                ax.set_axis_off()
                continue
            approach, trial, chosen = group[col]
            strip = not is_map_elites(approach)
            shape = (1, STRIP_PATHS) if strip else (DOWNSAMPLED, DOWNSAMPLED)
            lines = draw_paths(ax, chosen, shape, norm, label_size=MIN_FONT_PT)
            ax.set_title(f"{label(approach)}, {label(fitness)}: {trial.trial_key}")
    fig.colorbar(lines, ax=axes.ravel().tolist(), shrink=0.6, label=LOSS_LABEL, extend="max")
    fig.suptitle(study_title(grid, fitness))
    return ReportFigure(
        name=f"paths_{fitness}",
        title=f"Example paths, {label(fitness)}",
        caption=(
            "Foot paths from each approach's best trial. MAP-Elites: the repertoire "
            "downsampled to 5 × 5 with the best path of each region; NSGA-II: up to 5 "
            "paths evenly spaced along the final Pareto front (fewer when the front holds "
            "fewer linkages); EA: the 5 best paths of the final population. Each path is "
            "scaled to fit its cell; the corner number is its size (the larger of width "
            "and height, in LEGO units); colour is the single-objective loss. Where a "
            "linkage fails to assemble at some crank angles, its path has a gap there "
            "(the foot goes nowhere), not a straight chord."
        ),
        figure=fig,
    )


def convergence_figure(grid: GridData) -> ReportFigure | None:
    """Returns best loss, coverage and QD-score (own and common grid) against evaluations,
    median and IQR band.

    Rows are measures, columns fitness functions; finished trials only. None when no
    history was logged.
    """
    history = grid.history[grid.history.status == "FINISHED"]
    metrics = [
        (m, name) for m, name in CONVERGENCE_METRICS if m in history and history[m].notna().any()
    ]
    if history.empty or not metrics:
        return None
    fitnesses = grid.fitnesses()
    fig = Figure(figsize=(PAGE_WIDTH_IN, 2.0 * len(metrics) + 1.0), layout="constrained")
    axes = fig.subplots(len(metrics), len(fitnesses), squeeze=False, sharex=True)
    for col, fitness in enumerate(fitnesses):
        for row, (metric, name) in enumerate(metrics):
            ax = axes[row, col]
            for i, approach in enumerate(grid.approaches()):
                part = history[(history.fitness == fitness) & (history.approach == approach)]
                part = part[part[metric].notna()]
                if part.empty:
                    continue
                by_step = part.groupby("iteration")
                x = by_step.evaluations.median()
                q = by_step[metric].quantile([0.25, 0.5, 0.75]).unstack()
                ax.plot(x, q[0.5], lw=1.2, label=label(approach), color=f"C{i}")
                ax.fill_between(x, q[0.25], q[0.75], color=f"C{i}", alpha=0.2, lw=0)
            ax.set_title(f"{name}, {label(fitness)}")
            ax.set_ylabel(f"{'lower' if metric in LOWER_IS_BETTER else 'higher'} is better")
            ax.xaxis.set_major_locator(MaxNLocator(4))
            thousands(ax)
            ax.tick_params(labelbottom=True)
            ax.grid(alpha=0.3)
        axes[-1, col].set_xlabel("evaluations")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    if handles:
        band = Patch(color="0.5", alpha=0.3, label="band: 25th-75th percentile of the trials")
        handles, labels = [*handles, band], [*labels, band.get_label()]
        fig.legend(handles, labels, loc="outside lower center", ncols=min(len(handles), 4))
    fig.suptitle(study_title(grid))
    return ReportFigure(
        name="convergence",
        title="Convergence",
        caption=(
            "Per approach, against evaluations: the median over finished trials (line) "
            "and the inter-quartile range, 25th to 75th percentile, (shaded band) of the "
            "best loss, the coverage and QD-score on the approach's own grid, and the "
            "coverage and QD-score on the common grid. Own grid: the repertoire for "
            "MAP-Elites and RANDOM (it only grows; MAP-AU's is re-placed at each "
            "retraining, hence its saw-tooth), the current population on the MAP-LIS grid "
            "for the EA and NSGA-II (it can fall). Common grid: every genome the approach "
            "evaluated, binned on the MAP-LIS grid (cumulative for every approach, so the "
            "rows compare across approaches)."
        ),
        figure=fig,
    )
