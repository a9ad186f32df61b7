"""Provides `linkevo eval` (score a genome file) and `linkevo show` (draw one linkage)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from linkevo.orchestrator.cli import CliError
from linkevo.sim.genome import GenomeError, validate_genomes
from linkevo.sim.study import DEFAULT_ANGLES, FITNESSES, MIN_ANGLES, MODES
from linkevo.workers.plots.linkage import SUFFIXES


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `eval` and `show` subcommands."""
    ev = subparsers.add_parser(
        "eval",
        help="evaluate a .npy file of genomes",
        description="Decode, simulate and score genomes (N, 56); write the results as npz.",
    )
    ev.add_argument("genomes", type=Path, help="a .npy file holding an (N, 56) float array")
    ev.add_argument("--fitness", choices=FITNESSES, default="Fp", help="loss to compute")
    ev.add_argument("--mode", choices=MODES, default="paper", help="spec mode")
    ev.add_argument("--target", default="D16", help="D16 (default), D24 or a JSON target file")
    ev.add_argument(
        "--angles",
        type=int,
        default=DEFAULT_ANGLES,
        help=f"crank angles per turn (>= {MIN_ANGLES})",
    )
    ev.add_argument("--out", type=Path, required=True, help="the result .npz file")
    ev.set_defaults(func=run_eval)

    show = subparsers.add_parser(
        "show",
        help="draw a linkage as PNG or GIF",
        description="Draw a linkage document (.json) or one row of a genome file (.npy[:ROW]).",
    )
    show.add_argument("source", help="LINKAGE.json or GENOMES.npy[:ROW] (row 0 by default)")
    show.add_argument("--mode", choices=MODES, default=None, help="for .npy input (default paper)")
    show.add_argument(
        "--angles",
        type=int,
        default=DEFAULT_ANGLES,
        help=f"crank angles per turn (>= {MIN_ANGLES})",
    )
    show.add_argument("--out", type=Path, required=True, help="FILE.png (still) or FILE.gif")
    show.set_defaults(func=run_show)


def load_genomes(path: Path) -> np.ndarray:
    """Returns the validated (N, 56) genomes stored in a .npy file, or raises CliError."""
    if path.suffix != ".npy" or not path.is_file():
        raise CliError(f"genome file {str(path)!r} must be an existing .npy file")
    try:
        genomes = np.load(path, allow_pickle=False)
    except ValueError as exc:
        raise CliError(f"cannot read {str(path)!r} as a numeric .npy array: {exc}") from exc
    try:
        genomes = validate_genomes(genomes)
    except GenomeError as exc:
        raise CliError(f"{path}: {exc}") from exc
    if len(genomes) == 0:
        raise CliError(f"{path} holds no genomes (shape {genomes.shape}); allowed: (N, 56), N >= 1")
    return genomes


def check_writable(path: Path, suffixes: tuple[str, ...]) -> None:
    """Raises CliError unless `path` has an allowed suffix and its folder is writable."""
    if path.suffix.lower() not in suffixes:
        raise CliError(f"output {str(path)!r} must end in one of {', '.join(suffixes)}")
    folder = path.resolve().parent
    if not folder.is_dir():
        raise CliError(f"output folder {str(folder)!r} does not exist")


def check_angles(angles: int) -> None:
    """Raises CliError unless `angles` (crank angles per turn) is at least MIN_ANGLES."""
    if angles < MIN_ANGLES:
        raise CliError(f"--angles must be >= {MIN_ANGLES}, got {angles}")


def run_eval(args: argparse.Namespace) -> int:
    """Handles `linkevo eval`."""
    from linkevo.sim.evaluate import evaluate
    from linkevo.workers.evaluators import resolve_target
    from linkevo.workers.store.artifacts import write_npz_atomic

    genomes = load_genomes(args.genomes)
    check_writable(args.out, (".npz",))
    check_angles(args.angles)
    try:
        target = resolve_target(args.target)
    except ValueError as exc:
        raise CliError(str(exc)) from exc
    ev = evaluate(genomes, args.fitness, args.mode, target, args.angles)
    arrays = {
        "loss": ev.loss,
        "error": ev.error,
        "angle_error": ev.angle_error,
        "valid": ev.valid,
        "foot": ev.foot,
        "foot_x": ev.foot_x,
        "foot_y": ev.foot_y,
    }
    for name, values in ev.descriptors.items():
        arrays[f"desc_{name}"] = values
    write_npz_atomic(args.out, arrays)
    print(
        f"evaluated {len(genomes)} genomes ({args.fitness}, {args.mode} mode): "
        f"{int((ev.error == 0).sum())} valid, best loss {np.min(ev.loss, axis=0)} -> {args.out}"
    )
    return 0


def run_show(args: argparse.Namespace) -> int:
    """Handles `linkevo show`."""
    from linkevo.sim.linkage_doc import from_document
    from linkevo.workers.plots.linkage import draw_linkage

    check_writable(args.out, SUFFIXES)
    check_angles(args.angles)
    source = args.source
    if source.endswith(".json"):
        path = Path(source)
        try:
            genome, mode = from_document(json.loads(path.read_text()))
        except (OSError, json.JSONDecodeError, ValueError) as exc:
            raise CliError(f"cannot load linkage document {source!r}: {exc}") from exc
        mode = args.mode or mode
    else:
        file, _, row_text = source.partition(":")
        genomes = load_genomes(Path(file))
        try:
            row = int(row_text or 0)
            genome = genomes[row]
        except (ValueError, IndexError) as exc:
            raise CliError(
                f"row {row_text!r} is not an index into {file} ({len(genomes)} rows)"
            ) from exc
        mode = args.mode or "paper"
    draw_linkage(genome, mode, args.out, n_angles=args.angles)
    print(f"wrote {args.out}")
    return 0
