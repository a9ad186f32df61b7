"""Provides `render_html`: one self-contained HTML page with the figures embedded."""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence

import pandas as pd

from linkevo.orchestrator.report.verdicts import REPRODUCED, Finding
from linkevo.sim.linkage.physical import BUILDABLE_STRETCH, TOGGLE_DEG
from linkevo.sim.study import STUDY_EVALUATIONS

MIN_TRIALS_PER_CELL = 5
"""Below this many finished trials a cell's statistics are flagged as weak."""

STYLE = """
body { font-family: sans-serif; max-width: 1200px; margin: 2em auto; color: #222; }
table { border-collapse: collapse; font-size: 0.8em; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #ccc; padding: 2px 6px; text-align: right; }
th { background: #f3f3f3; }
td.text { text-align: left; }
img { max-width: 100%; }
.reproduced { color: #196619; font-weight: bold; }
.other { color: #a33; font-weight: bold; }
.warn { background: #fff3e0; padding: 0.5em; border-left: 4px solid #e69500; }
figcaption { font-size: 0.85em; color: #444; margin-bottom: 2em; }
"""


def table_html(frame: pd.DataFrame) -> str:
    """Returns an HTML table of `frame` (floats to 4 significant digits)."""
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in frame.columns)
    rows = []
    for record in frame.itertuples(index=False):
        cells = []
        for value in record:
            if isinstance(value, float):
                cells.append(f"<td>{value:.4g}</td>")
            else:
                cells.append(f'<td class="text">{html.escape(str(value))}</td>')
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(rows)}</table>"


def context(config: dict, summary: pd.DataFrame) -> tuple[str, list[str]]:
    """Returns the sentence naming what the grid ran, and the warnings a reader needs.

    Warnings: a budget below the study's, and cells with fewer than MIN_TRIALS_PER_CELL
    finished trials.
    """
    budget = config.get("evaluations")
    approaches = config.get("approaches") or sorted(summary.approach.unique())
    fitnesses = config.get("fitnesses") or sorted(summary.fitness.unique())
    said = (
        f"Budget {budget:,} evaluations per trial (batches of {config.get('batch_size')}), "
        if isinstance(budget, int)
        else "Budget unknown, "
    )
    said += (
        f"mode {config.get('mode', '?')}, target {config.get('target', '?')}, "
        f"{config.get('trials', '?')} trials per approach and fitness; approaches "
        f"{', '.join(approaches)}; fitness {', '.join(fitnesses)}."
    )
    warnings = []
    if isinstance(budget, int) and budget < STUDY_EVALUATIONS:
        warnings.append(
            f"The budget, {budget:,} evaluations per trial, is below the study's "
            f"{STUDY_EVALUATIONS:,}: the numbers are not the study's answer."
        )
    thin = summary[summary.n_finished < MIN_TRIALS_PER_CELL]
    if len(thin):
        cells = ", ".join(
            f"{r.approach}/{r.fitness} ({r.n_finished})" for r in thin.itertuples(index=False)
        )
        warnings.append(
            f"Fewer than {MIN_TRIALS_PER_CELL} finished trials in {cells}: their statistics "
            "are weak."
        )
    return said, warnings


def render_html(
    *,
    grid_id: str,
    parent_run_id: str,
    tracking_uri: str,
    config: dict,
    config_text: str,
    figures: Sequence[tuple[str, str, bytes]],
    summary: pd.DataFrame,
    tests: pd.DataFrame,
    trials: pd.DataFrame,
    findings: Sequence[Finding],
    checks: pd.DataFrame,
    winners: pd.DataFrame | None = None,
) -> str:
    """Returns the report page; every image is inlined as a base64 PNG data URI.

    Args:
        grid_id: the grid's id.
        parent_run_id: the grid's parent MLflow run.
        tracking_uri: the store the grid was read from.
        config: the grid's resolved config.
        config_text: the same as TOML, shown in full.
        figures: (title, caption, PNG bytes) per figure, in order.
        summary: `stats.summary_table`.
        tests: `stats.pairwise_tests`.
        trials: per-trial table (trial_key, approach, fitness, status, error, best_loss).
        findings: `findings.check_findings`.
        checks: `checks.checks_summary` of the best linkages' physical checks.
        winners: `checks.walking_winners` (None or empty: no walking trials).
    """
    unfinished = trials[trials.status != "FINISHED"]
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>linkevo report {html.escape(grid_id)}</title><style>{STYLE}</style></head><body>",
        f"<h1>Grid {html.escape(grid_id)}</h1>",
        f"<p>Parent run <code>{html.escape(parent_run_id)}</code> in "
        f"<code>{html.escape(tracking_uri)}</code>; {len(trials)} trials, "
        f"{int((trials.status == 'FINISHED').sum())} finished.</p>",
    ]
    said, warnings = context(config, summary)
    parts.append(f"<p class='context'>{html.escape(said)}</p>")
    parts += [f"<div class='warn'>{html.escape(w)}</div>" for w in warnings]
    parts.append(
        f"<details><summary>Config</summary><pre>{html.escape(config_text)}</pre></details>"
    )
    if len(unfinished):
        parts.append(
            f"<div class='warn'>{len(unfinished)} trials did not finish and are left out of "
            "the statistics and figures:</div>"
        )
        parts.append(table_html(unfinished[["trial_key", "status", "error"]].fillna("")))
    parts.append("<h2>The study's findings on this grid</h2><table>")
    parts.append("<tr><th>claim</th><th>verdict</th><th>rule</th><th>evidence</th></tr>")
    for f in findings:
        css = "reproduced" if f.verdict == REPRODUCED else "other"
        parts.append(
            f"<tr><td class='text'>{html.escape(f.claim)}</td>"
            f"<td class='text {css}'>{html.escape(f.verdict)}</td>"
            f"<td class='text'>{html.escape(f.rule)}</td>"
            f"<td class='text'>{html.escape(f.evidence)}</td></tr>"
        )
    parts.append("</table>")
    parts.append("<h2>Best loss per approach and fitness</h2>")
    parts.append(table_html(summary))
    parts.append(
        "<h2>Pairwise tests</h2><p>Two-sided Mann–Whitney U on the best-ever loss: exact "
        "where the pooled sample has no ties, else asymptotic (column <i>method</i>). "
        "Holm-corrected within each fitness and family (<i>study</i>: the study's "
        "approaches; <i>baseline</i>: each against RANDOM); A12 = P(loss_a &gt; loss_b) + "
        "P(=)/2, so A12 &lt; 0.5 means approach a tends to lower (better) losses.</p>"
    )
    parts.append(table_html(tests))
    parts.append(
        "<h2>Can the best linkages be built?</h2><p>The physical checks of each trial's "
        "best-ever linkage (<code>sim.linkage.physical</code>; per trial in "
        "best_linkage_checks.csv): <i>buildable</i> linkages turn fully, pass no toggle "
        f"position (transmission angle below {TOGGLE_DEG:g} deg) and stretch no beam by more "
        f"than {BUILDABLE_STRETCH:g} modules within the simulation's tolerance. Size is the "
        "larger side of the box the linkage sweeps, in modules.</p>"
    )
    parts.append(table_html(checks))
    if winners is not None and len(winners):
        parts.append(winners_html(winners))
    for title, caption, png in figures:
        data = base64.b64encode(png).decode("ascii")
        parts.append(
            f"<h2>{html.escape(title)}</h2><figure><img alt='{html.escape(title)}' "
            f"src='data:image/png;base64,{data}'><figcaption>{html.escape(caption)}"
            "</figcaption></figure>"
        )
    parts.append("</body></html>")
    return "\n".join(parts)


def winners_html(winners: pd.DataFrame) -> str:
    """Returns the section on a walking grid's best walkers (`checks.walking_winners`), with
    the ones a builder should doubt named."""
    doubt = []
    for row in winners.itertuples():
        why = [
            text
            for flag, text in (
                (row.best_models_agree == 0, "the full model disagrees with the lean one"),
                (row.best_chaotic == 1, "a chaotic gait"),
                (row.best_slides == 1, "its distance is mostly its feet sliding"),
            )
            if flag
        ]
        if why:
            doubt.append(f"<li>{html.escape(row.trial_key)}: {html.escape('; '.join(why))}</li>")
    listed = f"<p>Doubt these:</p><ul>{''.join(doubt)}</ul>" if doubt else ""
    return (
        "<h2>Do the walking winners walk?</h2><p>Each walking trial's best walker, walked "
        "again on the full model from five hand-placed starts per floor "
        "(walking_winners.csv): its credited distance per 10 s on the lean model "
        "(<i>best_flat_cm</i>, <i>best_carpet_cm</i>) and on the full one, whether the two "
        "agree within 30 %, whether its repeats scatter (<i>chaotic</i>) or its feet slip at "
        "over half the body's speed (<i>slides</i>), and its leg's width, stroke and crank "
        "share (1: the foot rides the crank as a wheel's rim). NaN: the best did not walk "
        f"soundly on both floors.</p>{listed}" + table_html(winners)
    )
