"""Provides `draw_predicted_vs_walked`: a walk model's predicted distance against the
distance walked, per floor, on repertoires it never saw."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from linkevo.algorithms.walk_model import Prediction, WalkData
from linkevo.sim.robot.walk_rows import FLOOR_ORDER
from linkevo.workers.store.artifacts import atomic_path


def draw_predicted_vs_walked(
    prediction: Prediction, truth: WalkData, figures: dict[str, float], path: Path
) -> Path:
    """Draws, a panel per floor, each held-out cell that walks without breaking as a dot
    (walked cm in 10 s across, predicted up, the diagonal for a perfect model) and each
    that breaks in red at its walked-as-0 place; writes a PNG at `path` atomically."""
    fig = Figure(figsize=(4.2 * len(FLOOR_ORDER), 4.2))
    for k, floor in enumerate(FLOOR_ORDER):
        ax = fig.add_subplot(1, len(FLOOR_ORDER), k + 1)
        sound = np.isfinite(truth.distance[:, k])
        broke = truth.breaks[:, k] == 1.0
        walked, predicted = truth.distance[sound, k], prediction.distance[sound, k]
        ax.scatter(walked, predicted, s=3, alpha=0.35, color="#3b6ea8", label="walks")
        ax.scatter(
            np.zeros(broke.sum()),
            prediction.distance[broke, k],
            s=3,
            alpha=0.35,
            color="#e34a33",
            label="breaks (walked as 0)",
        )
        both = np.concatenate([walked, predicted, [0.0, 1.0]])
        low, high = float(np.nanmin(both)), float(np.nanmax(both))
        ax.plot([low, high], [low, high], color="0.4", linewidth=0.8)
        ax.set_title(
            f"{floor}: Spearman {figures.get(f'spearman_{floor}', np.nan):.2f} "
            f"({int(sound.sum())} walk), break AUC "
            f"{figures.get(f'break_auc_{floor}', np.nan):.2f}",
            fontsize=8,
        )
        ax.set_xlabel("walked in 10 s (cm, simulated robot)", fontsize=7)
        ax.set_ylabel("predicted (cm)", fontsize=7)
        ax.tick_params(labelsize=6)
        ax.legend(fontsize=6, loc="upper left")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=120)
    return path
