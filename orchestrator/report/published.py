"""Provides `table_findings`, `changed_claims` and `add_measures`: a report's claims
recomputed from its folder's tables alone (no store), and the per-trial measures a
published `trials.csv` lacks taken from a rerun of the same trials."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from linkevo.orchestrator.report.build import LOGGED_COLUMNS
from linkevo.orchestrator.report.compare import TrialsTableError, read_trials_csv
from linkevo.orchestrator.report.findings import MEASURES, check_findings
from linkevo.orchestrator.report.stats import pairwise_tests
from linkevo.sim.errors import LinkevoError

REPRODUCED_COLUMNS: tuple[str, ...] = ("seed", *LOGGED_COLUMNS)
"""What a rerun trial must log exactly as the published one did for its measures to be
taken as the published trial's (a trial is a function of its seed)."""


def read_folder(folder: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Returns a report folder's trials table (with every `MEASURES` column; NaN where
    the table predates one) and its best paths' sizes (`path_sizes.csv`).

    Raises:
        TrialsTableError: naming the file, when a table is missing or not a report's.
    """
    trials = read_trials_csv(str(folder / "trials.csv"))
    try:
        sizes = pd.read_csv(folder / "path_sizes.csv")
    except (OSError, ValueError) as exc:
        raise TrialsTableError(
            f"{folder / 'path_sizes.csv'} is not a readable table ({exc}); allowed: a "
            "report's folder (docs/results/*/)"
        ) from exc
    for column in MEASURES:
        if column not in trials:
            trials[column] = np.nan
    return trials, sizes


def table_findings(trials: pd.DataFrame, sizes: pd.DataFrame) -> pd.DataFrame:
    """Returns the study's claims judged on a report folder's tables (`read_folder`) as
    `linkevo report` judges them from the store (`findings.check_findings`), as its
    findings.csv holds them (text columns); a claim whose per-trial measure the table
    lacks reads "not testable". A table does not say its budget: its trials are judged."""
    findings = check_findings(trials, sizes, pairwise_tests(trials), None)
    return pd.DataFrame([f.__dict__ for f in findings]).fillna("").astype(str)


def changed_claims(findings: pd.DataFrame, published: pd.DataFrame) -> list[str]:
    """Returns "NUMBER FITNESS" of each claim whose row in `findings` (`table_findings`)
    differs from a findings.csv's (read as text), in order; a different number of claims
    is one entry too."""
    published = published.fillna("").astype(str)
    changed = [
        f"{row.number} {row.fitness}".strip()
        for row, old in zip(
            findings.itertuples(index=False), published.itertuples(index=False), strict=False
        )
        if tuple(row) != tuple(old)
    ]
    if len(findings) != len(published):
        changed.append(f"{len(findings)} claims against {len(published)}")
    return changed


class NotReproduced(LinkevoError, ValueError):
    """A rerun trial that did not log what its published trial did."""


def add_measures(published: pd.DataFrame, reruns: pd.DataFrame) -> pd.DataFrame:
    """Returns the published trials table with the `MEASURES` of its finished trials
    taken from a rerun of them (a report's `trials.csv` of a grid run again from the same
    seeds, in any split: several reports' tables concatenated); trials not rerun keep
    what they had.

    Args:
        published: a report's trials table (`read_folder`), N rows.
        reruns: report trials tables with `MEASURES`, one row per rerun trial key.

    Raises:
        NotReproduced: naming the trial, the column and both values, when a rerun
            trial's `REPRODUCED_COLUMNS` differ from the published trial's: its measures
            would not be the published trial's.
    """
    done = reruns[reruns.status == "FINISHED"].drop_duplicates("trial_key", keep="last")
    mine = published.set_index("trial_key")
    rerun = done.set_index("trial_key")
    shared = [k for k in mine.index[mine.status == "FINISHED"] if k in rerun.index]
    for key in shared:
        for column in REPRODUCED_COLUMNS:
            was, now = mine.at[key, column], rerun.at[key, column]
            if not (was == now or (pd.isna(was) and pd.isna(now))):
                raise NotReproduced(
                    f"trial {key}: the rerun logged {column} {now}, the published table "
                    f"{was}; only a rerun from the same seed at code that reproduces it "
                    "can give its measures"
                )
    for column in MEASURES:
        mine.loc[shared, column] = rerun.loc[shared, column].to_numpy()
    return mine.reset_index()[published.columns]
