"""Check: what linkevo writes is unchanged by a change of its code (a refactor must leave
every output as it was).

Runs the same commands on this tree and, with `--against TREE`, on another checkout (made
with `git worktree add ../base HEAD~3`, say), through the command line only, so it holds
across moved modules, and prints a digest per output and whether the two trees agree:

- a trial of every approach with F_p and F_sl at a small budget, and with F_w (with and
  without the walk model's screen for MAP-LIS), each trial's files;
- 30 reference walks (`hexapod simulate --json`: three legs, two floors, five repeats) and
  two on the full model;
- a walk map of the 40 lowest-loss buildable cells of a MAP-LIS repertoire.

Timing columns (seconds a candidate took, the node it ran on, wall times) are left out of
the digests; everything else counts. Pictures are digested by their pixels, torch files by
their tensors (`torch.save` writes a random id into every file).

Run: `.venv/bin/python benchmarks/output_digests.py [--against TREE] [--only trials]`
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))
from trees import tree_env

HERE = Path(__file__).resolve().parents[1]
APPROACHES = ("EA", "NSGA2", "MAP-WH", "MAP-LIS", "MAP-ST", "MAP-AU", "RANDOM")
TIMING = ("compute_s", "node", "seconds_taken", "wall_s", "elapsed", "duration", "time_s")
LEGS = ("benchmarks/walk_linkage.json", "tests/data/sound_leg.json")


def digest_file(path: Path) -> str:
    """Returns a digest of a file's content, timing columns and keys left out."""
    h = hashlib.sha1()
    if path.suffix == ".parquet":
        frame = pd.read_parquet(path)
        frame = frame.drop(columns=[c for c in frame.columns if c in TIMING])
        h.update(frame.to_csv(index=False).encode())
    elif path.suffix == ".csv":
        frame = pd.read_csv(path)
        frame = frame.drop(columns=[c for c in frame.columns if c in TIMING])
        h.update(frame.to_csv(index=False).encode())
    elif path.suffix == ".json":
        h.update(json.dumps(_untimed(json.loads(path.read_text())), sort_keys=True).encode())
    elif path.suffix == ".pt":  # a torch file's bytes hold a random id: digest its tensors
        import torch

        state = torch.load(path, weights_only=True)
        for name in sorted(state):
            h.update(name.encode())
            h.update(state[name].numpy().tobytes())
    elif path.suffix == ".png":
        from PIL import Image

        with Image.open(path) as image:
            h.update(np.asarray(image.convert("RGBA")).tobytes())
    else:
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _untimed(value):
    if isinstance(value, dict):
        return {k: _untimed(v) for k, v in value.items() if not any(t in k for t in TIMING)}
    if isinstance(value, list):
        return [_untimed(v) for v in value]
    return value


def linkevo(tree: Path, work: Path, *words: str) -> str:
    """Runs linkevo from `tree` and returns what it printed (raises on a failure)."""
    env = tree_env(tree, work)
    done = subprocess.run(
        [sys.executable, "-m", "linkevo.orchestrator", *words],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode:
        raise RuntimeError(f"linkevo {' '.join(words)}: {done.stderr[-2000:]}")
    return done.stdout


def trial_digests(tree: Path, work: Path) -> dict[str, str]:
    """Every approach with F_p, F_sl and F_w at a small budget; MAP-LIS F_w screened."""
    runs = []
    for approach in APPROACHES:
        options = ["--option", "initial_epochs=20", "--option", "retrain_epochs=5"]
        options = options if approach == "MAP-AU" else []
        for fitness in ("Fp", "Fsl"):
            runs.append(
                (
                    f"{approach}/{fitness}",
                    ["--evaluations", "2000", "--batch-size", "500", *options],
                    fitness,
                )
            )
        runs.append((f"{approach}/Fw", ["--walks", "24", "--batch-size", "8", *options], "Fw"))
    runs.append(("MAP-LIS/Fw/screen", ["--walks", "232", "--surrogate"], "Fw"))
    out = {}
    for name, extra, fitness in runs:
        folder = work / name.replace("/", "_")
        approach = name.split("/")[0]
        linkevo(
            tree,
            work,
            "trial",
            "--approach",
            approach,
            "--fitness",
            fitness,
            "--seed",
            "3",
            "--out",
            str(folder),
            "--no-progress",
            *extra,
        )
        for path in sorted(folder.iterdir()):
            if path.is_file() and path.name != "result.json":
                out[f"trial {name} {path.name}"] = digest_file(path)
    return out


def walk_digests(tree: Path, work: Path) -> dict[str, str]:
    """30 lean walks (three legs, two floors, five repeats, 3 s) and two full-model walks."""
    legs = [str(HERE / leg) for leg in LEGS]
    extra = work / "trial_MAP-LIS_Fw" / "best_linkage.json"
    legs.append(str(extra) if extra.exists() else legs[0])
    out = {}
    for leg in legs:
        for floor in ("flat", "carpet"):
            text = linkevo(
                tree,
                work,
                "hexapod",
                "simulate",
                "--linkage",
                leg,
                "--floor",
                floor,
                "--seconds",
                "3",
                "--repeats",
                "5",
                "--json",
                "--no-log",
            )
            out[f"walks {Path(leg).parent.name}/{Path(leg).name} {floor} lean"] = _text_digest(text)
    text = linkevo(
        tree,
        work,
        "hexapod",
        "simulate",
        "--linkage",
        legs[0],
        "--floor",
        "flat",
        "--seconds",
        "2",
        "--repeats",
        "2",
        "--model",
        "full",
        "--json",
        "--no-log",
    )
    out["walks full"] = _text_digest(text)
    return out


def _text_digest(text: str) -> str:
    return hashlib.sha1(
        json.dumps(_untimed(json.loads(text)), sort_keys=True).encode()
    ).hexdigest()[:16]


def walk_map_digest(tree: Path, work: Path) -> dict[str, str]:
    """A walk map of the 40 lowest-loss buildable cells of a small MAP-LIS F_p trial."""
    uri = f"sqlite:///{work / 'mlflow.db'}"
    linkevo(
        tree,
        work,
        "grid",
        str(HERE / "configs/quick.toml"),
        "--set",
        'approaches=["MAP-LIS"]',
        "--set",
        'fitnesses=["Fp"]',
        "--set",
        "trials=1",
        "--set",
        "evaluations=20000",
        "--set",
        "batch_size=2000",
        "--tracking-uri",
        uri,
        "--no-progress",
    )
    import mlflow

    client = mlflow.MlflowClient(uri)
    runs = client.search_runs(
        [e.experiment_id for e in client.search_experiments()],
        "tags.`linkevo.kind` = 'trial'",
    )
    run = runs[0].info.run_id
    linkevo(tree, work, "walkmap", run, "--cells", "best:40", "--tracking-uri", uri)
    path = Path(client.download_artifacts(run, "walkmap.parquet", str(work)))
    frame = pd.read_parquet(path)
    return {"walk map best:40": digest_file(path), "walk map rows": str(len(frame))}


def digests(tree: Path, only: str | None) -> dict[str, str]:
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        out = {}
        if only in (None, "trials"):
            out |= trial_digests(tree, work)
        if only in (None, "walks"):
            out |= walk_digests(tree, work)
        if only in (None, "walkmap"):
            out |= walk_map_digest(tree, work)
        return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--against", type=Path, default=None, help="another checkout")
    parser.add_argument("--only", choices=("trials", "walks", "walkmap"), default=None)
    parser.add_argument("--save", type=Path, default=None, help="write this tree's digests")
    args = parser.parse_args()
    mine = digests(HERE, args.only)
    if args.save:
        args.save.write_text(json.dumps(mine, indent=1, sort_keys=True))
    theirs = digests(args.against.resolve(), args.only) if args.against else {}
    same = 0
    for name, value in mine.items():
        other = theirs.get(name, "")
        mark = "" if not theirs else ("same" if other == value else f"DIFFERS from {other}")
        same += other == value
        print(f"{name:60s} {value} {mark}")
    if theirs:
        print(f"{same} of {len(mine)} outputs identical ({len(theirs)} on the other tree)")


if __name__ == "__main__":
    main()
