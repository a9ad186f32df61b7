"""Tests the grid expansion: trial keys, deterministic seeds, grid ids, the dry run."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from linkevo.orchestrator.cli import main
from linkevo.orchestrator.config import GridConfig
from linkevo.orchestrator.grid import Grid, trial_seed

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def test_cells_cover_every_approach_fitness_and_trial_once():
    grid = Grid.from_config(
        GridConfig(trials=3, approaches=("EA", "MAP-LIS"), fitnesses=("Fp", "Fsl")), "v1"
    )
    keys = [c.key for c in grid.cells]
    assert len(keys) == len(set(keys)) == 12
    assert keys[0] == "EA/Fp/00"
    assert "MAP-LIS/Fsl/02" in keys
    assert grid.cell("MAP-LIS/Fsl/02").dirname == "MAP-LIS_Fsl_02"
    with pytest.raises(KeyError):
        grid.cell("MAP-LIS/Fsl/03")


def test_seeds_depend_on_grid_seed_and_cell_only():
    small = Grid.from_config(GridConfig(trials=2, approaches=("MAP-LIS",)), "v1")
    large = Grid.from_config(GridConfig(trials=5, approaches=("EA", "MAP-LIS")), "v1")
    for cell in small.cells:
        assert large.cell(cell.key).seed == cell.seed
    seeds = [c.seed for c in large.cells]
    assert len(set(seeds)) == len(seeds)
    assert trial_seed(0, "EA", "Fp", 0) != trial_seed(1, "EA", "Fp", 0)
    assert all(0 <= s < 2**32 for s in seeds)


def test_grid_id_hashes_results_config_and_code_version():
    cfg = GridConfig(trials=2)
    grid_id = Grid.from_config(cfg, "v1").grid_id
    assert len(grid_id) == 12
    assert Grid.from_config(GridConfig(trials=2), "v1").grid_id == grid_id
    assert Grid.from_config(GridConfig(trials=2, max_concurrent_trials=7), "v1").grid_id == grid_id
    assert Grid.from_config(cfg, "v2").grid_id != grid_id
    assert Grid.from_config(GridConfig(trials=2, evaluations=10), "v1").grid_id != grid_id
    assert (
        Grid.from_config(GridConfig(trials=30), "v1").grid_id
        == Grid.from_config(GridConfig(trials=10), "v1").grid_id
    )  # more trials extend a grid


def test_dry_run_prints_the_plan_and_starts_nothing(tmp_path, capsys):
    db = tmp_path / "store"
    code = main(
        [
            "grid",
            str(CONFIGS / "quick.toml"),
            "--dry-run",
            "--set",
            "trials=2",
            "--tracking-uri",
            str(db),
        ]
    )
    out = capsys.readouterr().out
    assert code == 0
    assert "24 trials" in out
    assert "MAP-AU/Fsl/01" in out
    assert "trials = 2" in out
    assert not db.exists()


def test_the_commands_it_prints_run_as_this_one_was_run(monkeypatch, tmp_path):
    from linkevo.orchestrator.commands.options import linkevo_command

    venv_linkevo = Path(sys.executable).parent / "linkevo"
    monkeypatch.setattr(sys, "argv", [str(venv_linkevo), "grid"])
    monkeypatch.setenv("PATH", "/usr/bin:/bin")  # an environment that is not activated
    monkeypatch.chdir(tmp_path)
    assert linkevo_command("ui") == f"{venv_linkevo} ui"
    monkeypatch.setenv("PATH", f"{venv_linkevo.parent}:/usr/bin:/bin")
    assert linkevo_command("walkmap", "a b") == "linkevo walkmap 'a b'"
    monkeypatch.chdir(venv_linkevo.parents[2])  # the checkout: a path the shell runs as typed
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    assert linkevo_command() == str(venv_linkevo.relative_to(venv_linkevo.parents[2]))
    monkeypatch.setattr(sys, "argv", ["-c", "grid"])
    assert linkevo_command().endswith("-m linkevo.orchestrator")
