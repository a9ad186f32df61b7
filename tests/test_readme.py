"""Tests that the README's set-up commands stay true to the project's files."""

from __future__ import annotations

import re
import shlex
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def readme_commands() -> list[str]:
    """Returns the shell commands of the README's first two bash blocks."""
    text = (ROOT / "README.md").read_text()
    return [block.strip() for block in re.findall(r"```bash\n(.*?)```", text, re.S)[:2]]


def test_ci_runs_the_readme_test_command_verbatim():
    _, tests = readme_commands()
    ci_lines = (ROOT / ".ci" / "run").read_text().strip().splitlines()
    assert ci_lines[-1] == tests
    assert any("ruff check" in line for line in ci_lines)
    assert any("ruff format --check" in line for line in ci_lines)
    assert "pytest" in tests


def test_main_command_names_files_and_a_command_that_exist():
    main_job, _ = readme_commands()
    words = shlex.split(main_job.replace("&&", " "))
    config = next(w for w in words if w.endswith(".toml"))
    assert (ROOT / config).is_file()
    assert "-c" in words and (ROOT / words[words.index("-c") + 1]).is_file()
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert ".venv/bin/linkevo" in words and "linkevo" in scripts


def test_constraints_pin_the_cpu_torch_build():
    pins = (ROOT / "constraints.txt").read_text()
    assert re.search(r"^torch==2\.13\.0$", pins, re.M)
