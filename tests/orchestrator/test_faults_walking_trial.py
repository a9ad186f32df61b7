"""A walking trial (fitness F_w) under faults: budgets beyond the limit, a screen that would
never screen, two trials writing one folder; each refused before any walk, with one line."""

from __future__ import annotations

import pytest

from linkevo.workers.store.artifacts import writer_lock
from tests.helpers.faults import refused, snapshot


def trial(out, *words: str) -> list[str]:
    return [*f"trial --approach MAP-LIS --fitness Fw --out {out} --no-progress".split(), *words]


@pytest.mark.parametrize(
    ("words", "said"),
    [
        (["--walks", "1e12"], "argument --walks: invalid int value: '1e12'"),
        (["--walks", "20000000"], "walks must be an integer in [1, 10,000,000], got 20000000"),
        (["--walks", "150", "--surrogate"], "the walk model is first fitted after 200 walks"),
        (["--walks", "2", "--max-seconds", "nan"], "max_seconds must be a positive number"),
    ],
)
def test_a_walking_trials_bad_budget_is_refused(tmp_path, capsys, words, said):
    assert said in refused(trial(tmp_path / "out", *words), capsys)
    assert snapshot(tmp_path / "out") == {}


def test_a_second_trial_on_a_folder_being_written_is_refused_naming_the_first(tmp_path, capsys):
    out = tmp_path / "out"
    with writer_lock(out, "linkevo trial"):  # the first trial, still running
        before = snapshot(out)
        said = refused(trial(out, "--walks", "2", "--resume"), capsys)
        assert "is being written by pid" in said and "on " in said
        assert snapshot(out) == before
