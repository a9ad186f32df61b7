"""Provides `tree_env`: the environment that runs another checkout's linkevo with this
interpreter, so a benchmark can time two trees in one run (today's code against a change).

The package is imported from the tree through a folder holding `linkevo/<layer>` links to
the tree's layer folders, put first on PYTHONPATH (as the installed namespace maps them).
Make the other tree with `git worktree add ../base HEAD~3`, say.
"""

from __future__ import annotations

import os
from pathlib import Path

LAYERS = ("sim", "algorithms", "workers", "orchestrator", "hardware", "configs")


def tree_env(tree: Path, work: Path) -> dict[str, str]:
    """Returns os.environ with PYTHONPATH pointing `linkevo` at `tree`'s layers."""
    names = work / f"names-{abs(hash(str(tree.resolve())))}" / "linkevo"
    names.mkdir(parents=True, exist_ok=True)
    for layer in LAYERS:
        link = names / layer
        if (tree / layer).is_dir() and not link.exists():
            link.symlink_to(tree.resolve() / layer, target_is_directory=True)
    return {**os.environ, "PYTHONPATH": str(names.parent)}
