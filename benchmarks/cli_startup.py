"""Benchmark: how long `linkevo` takes to start before it does any work.

Run from the repository root:

    .venv/bin/python benchmarks/cli_startup.py [--against ../base] [--rounds 7]

Times, as whole processes, `linkevo --help` and `linkevo grid configs/quick.toml --dry-run`
(the dry run checks every trial's spec and the store, starts nothing): the median of
`--rounds` runs of each, this tree's code and, with `--against TREE` (another checkout,
`git worktree add ../base REV`), that tree's, the two taking turns, with the median ratio.
The target is under 1.5 s for both.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from trees import tree_env  # benchmarks/trees.py, beside this script

REPO = Path(__file__).resolve().parents[1]
COMMANDS = {
    "linkevo --help": ["--help"],
    "linkevo grid configs/quick.toml --dry-run": ["grid", "configs/quick.toml", "--dry-run"],
}


def seconds(words: list[str], env: dict[str, str] | None) -> float:
    """Returns the wall time of one `linkevo WORDS` process."""
    start = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "linkevo.orchestrator", *words],
        cwd=REPO,
        env=env,
        capture_output=True,
        check=True,
    )
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", type=Path, default=None, help="another checkout to time")
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="linkevo-startup-") as tmp:
        trees = {"this tree": tree_env(REPO, Path(tmp))}
        if args.against is not None:
            trees[str(args.against)] = tree_env(args.against, Path(tmp))
        for name, words in COMMANDS.items():
            times: dict[str, list[float]] = {tree: [] for tree in trees}
            for env in trees.values():
                seconds(words, env)  # warm the file cache and numba's
            for _ in range(args.rounds):
                for tree, env in trees.items():
                    times[tree].append(seconds(words, env))
            for tree, values in times.items():
                print(
                    f"{name}, {tree}: median {statistics.median(values):.2f} s "
                    f"(min {min(values):.2f}, max {max(values):.2f})"
                )
            if args.against is not None:
                ratios = [a / b for a, b in zip(*times.values(), strict=True)]
                print(f"  this tree / {args.against}: median ratio {statistics.median(ratios):.2f}")


if __name__ == "__main__":
    main()
