"""`linkevo trial`: a real small run, and bad input refused before any work starts."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from linkevo.orchestrator.cli import main

SMALL = ["--evaluations", "300", "--batch-size", "100", "--n-angles", "12", "--no-progress"]


def run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(["trial", *args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_cli_runs_a_trial_and_resumes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "trial"
    args = ["--approach", "MAP-LIS", "--fitness", "Fsl", "--seed", "3", "--out", str(out)]
    code, stdout, _ = run_cli([*args, *SMALL], capsys)
    assert code == 0
    assert "MAP-LIS Fsl: best loss" in stdout and "300 evaluations" in stdout
    for name in ("metrics.csv", "repertoire.parquet", "best_linkage.json", "best_linkage.png"):
        assert (out / name).is_file(), name
    settings = json.loads((out / "settings.json").read_text())
    assert settings["spec"]["fitness"] == "Fsl" and settings["spec"]["batch_size"] == 100
    first = (out / "metrics.csv").read_text()

    code, _, err = run_cli([*args, *SMALL], capsys)
    assert code == 2 and "already holds a trial; pass --resume" in err

    more = [a if a != "300" else "500" for a in SMALL]
    code, stdout, _ = run_cli([*args, *more, "--resume"], capsys)
    assert code == 0 and "500 evaluations" in stdout
    assert (out / "metrics.csv").read_text().startswith(first)


def test_cli_passes_approach_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ea"
    args = [
        "--approach",
        "EA",
        "--fitness",
        "Fp",
        "--out",
        str(out),
        "--option",
        "initial_sigma=0.05",
    ]
    code, _, _ = run_cli([*args, *SMALL], capsys)
    assert code == 0
    assert json.loads((out / "settings.json").read_text())["optimizer"]["initial_sigma"] == 0.05


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        (["--approach", "GA"], "unknown approach 'GA'; allowed: EA, NSGA2, MAP-WH, MAP-LIS"),
        (["--fitness", "speed"], "unknown fitness 'speed'; allowed: Fp, Fsl"),
        (
            ["--evaluations", "-10"],
            "evaluations must be an integer >= the batch size (100), got -10",
        ),
        (
            ["--mode", "fast"],
            "argument --mode: invalid choice: 'fast' (choose from 'paper', 'legacy')",
        ),
        (["--option", "colour=3"], "unknown option(s) 'colour' for EA; allowed: coverage_space"),
        (["--option", "oops"], "--option 'oops' must look like KEY=VALUE"),
    ],
)
def test_cli_bad_input_is_refused_before_work(
    changes: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "never"
    base = ["--approach", "EA", "--fitness", "Fp", "--out", str(out), *SMALL]
    args = list(base)
    for flag, value in zip(changes[::2], changes[1::2], strict=True):
        if flag in args:
            args[args.index(flag) + 1] = value
        else:
            args += [flag, value]
    code, _, err = run_cli(args, capsys)
    assert code == 2
    assert message in err
    assert not out.exists()


def test_cli_refuses_an_unwritable_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    out = blocker / "trial"
    code, _, err = run_cli(
        ["--approach", "EA", "--fitness", "Fp", "--out", str(out), *SMALL], capsys
    )
    assert code == 2
    assert f"--out {str(out)!r}: {str(blocker)!r} is a file, not a folder" in err


def _damage_truncated_state(out: Path) -> str:
    state = out / "checkpoint" / "state.npz"
    state.write_bytes(state.read_bytes()[:200])
    return f"cannot resume from {state}: the file is damaged (BadZipFile"


def _damage_short_metrics(out: Path) -> str:
    metrics = out / "metrics.csv"
    lines = metrics.read_text().splitlines(keepends=True)
    metrics.write_text("".join(lines[:2]))
    return f"cannot resume from {metrics}: it holds 1 whole rows but the checkpoint counts 3"


def _damage_partial_row(out: Path) -> str:
    metrics = out / "metrics.csv"
    lines = metrics.read_text().splitlines(keepends=True)
    metrics.write_text("".join(lines[:2]) + lines[2][:15])
    return f"cannot resume from {metrics}: row 3 has"


@pytest.mark.parametrize(
    "damage", [_damage_truncated_state, _damage_short_metrics, _damage_partial_row]
)
def test_cli_resume_of_a_damaged_checkpoint_names_the_file_and_the_remedy(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], damage
) -> None:
    out = tmp_path / "trial"
    args = ["--approach", "EA", "--fitness", "Fp", "--out", str(out), *SMALL]
    args += ["--checkpoint-every", "1"]
    assert run_cli(args, capsys)[0] == 0
    expected = damage(out)
    code, _, err = run_cli([*args, "--resume"], capsys)
    assert code == 2, err
    assert expected in err and "without --resume" in err and "--restart-trial KEY" in err
    assert "Traceback" not in err
