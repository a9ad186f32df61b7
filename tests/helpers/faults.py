"""What every fault test asserts of a refusal: exit 2, one line naming what is wrong, no
traceback; and what it must leave as it was."""

from __future__ import annotations

from pathlib import Path

import pytest

from linkevo.orchestrator.cli import main


def refused(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """Runs linkevo with `argv`; asserts it refused (exit 2, one line of error, argparse's
    usage lines aside, no traceback) and returns that line."""
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2, (code, out, err)
    assert "Traceback" not in err
    lines = [line for line in err.strip().splitlines() if not line.startswith(("usage:", " "))]
    assert len(lines) == 1, err
    return lines[0]


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under `folder` (what a refusal must leave as it was)."""
    if not folder.exists():
        return {}
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}
