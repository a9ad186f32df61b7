"""Provides `linkevo eval` (score a genome file) and `linkevo show` (draw one linkage)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from linkevo.orchestrator.cli import CliError
from linkevo.orchestrator.commands import options
from linkevo.sim.study import DEFAULT_ANGLES, MIN_ANGLES, MODES, PATH_FITNESSES

if TYPE_CHECKING:
    import numpy as np


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `eval` and `show` subcommands."""
    ev = subparsers.add_parser(
        "eval",
        help="evaluate a .npy file of genomes",
        description="Decode, simulate and score genomes (N, 56); write the results as npz.",
    )
    ev.add_argument("genomes", type=Path, help="a .npy file holding an (N, 56) float array")
    ev.add_argument("--fitness", choices=PATH_FITNESSES, default="Fp", help="loss to compute")
    options.mode(ev)
    options.target(ev)
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
    options.mode(show, None, f"for .npy input: {', '.join(MODES)} (default paper)")
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
    import numpy as np

    from linkevo.sim.linkage.genome import GenomeError, validate_genomes

    if path.suffix != ".npy" or not path.is_file():
        raise CliError(f"genome file {str(path)!r} must be an existing .npy file")
    try:  # mapped, not read: a header that claims more rows than the file holds is refused
        genomes = np.array(np.load(path, mmap_mode="r", allow_pickle=False))
    except (ValueError, EOFError, OSError) as exc:
        reason = _npy_shortfall(path) or str(exc) or type(exc).__name__
        raise CliError(f"cannot read {str(path)!r} as a numeric .npy array: {reason}") from exc
    try:
        genomes = validate_genomes(genomes)
    except GenomeError as exc:
        raise CliError(f"{path}: {exc}") from exc
    if len(genomes) == 0:
        raise CliError(f"{path} holds no genomes (shape {genomes.shape}); allowed: (N, 56), N >= 1")
    return genomes


def _npy_shortfall(path: Path) -> str | None:
    """Says why a .npy file is shorter than its header promises (empty, or a header that
    claims more data than follows it); None when that is not the problem."""
    import numpy as np

    size = path.stat().st_size
    if size == 0:
        return "it is empty"
    try:
        with open(path, "rb") as handle:
            major, _ = np.lib.format.read_magic(handle)
            read = np.lib.format.read_array_header_1_0
            shape, _, dtype = (read if major == 1 else np.lib.format.read_array_header_2_0)(handle)
            data = size - handle.tell()
    except (ValueError, EOFError, OSError):
        return None
    claimed = int(np.prod(shape)) * dtype.itemsize
    if claimed <= data:
        return None
    return f"its header claims shape {shape} of {dtype} ({claimed:,} bytes), {data:,} bytes follow"


def check_writable(path: Path, suffixes: tuple[str, ...]) -> None:
    """Raises CliError unless `path` has an allowed suffix and its folder is writable."""
    if path.suffix.lower() not in suffixes:
        raise CliError(f"output {str(path)!r} must end in one of {', '.join(suffixes)}")
    folder = path.resolve().parent
    if not folder.is_dir():
        raise CliError(f"output folder {str(folder)!r} does not exist")


def check_angles(angles: int, n_genomes: int = 1) -> None:
    """Raises CliError unless `angles` (crank angles per turn) is at least MIN_ANGLES and
    the evaluation of `n_genomes` at that many angles fits in this machine's memory."""
    from linkevo.orchestrator.config import MEMORY_SHARE, machine_memory
    from linkevo.sim.linkage.evaluation import evaluation_bytes

    if angles < MIN_ANGLES:
        raise CliError(f"--angles must be >= {MIN_ANGLES}, got {angles}")
    need, have = evaluation_bytes(n_genomes, angles), machine_memory()
    if need > MEMORY_SHARE * have:
        most = int(MEMORY_SHARE * have // evaluation_bytes(n_genomes, 1))
        raise CliError(
            f"--angles {angles:,}: {n_genomes:,} genome(s) need about {need / 2**30:,.1f} GiB "
            f"at that many angles, more than half of this machine's {have / 2**30:.1f} GiB; "
            f"allowed: --angles from {MIN_ANGLES} to about {most:,}"
        )


def run_eval(args: argparse.Namespace) -> int:
    """Handles `linkevo eval`."""
    import numpy as np

    from linkevo.sim.linkage.evaluating import evaluate
    from linkevo.workers.evaluators import resolve_target
    from linkevo.workers.store.artifacts import write_npz_atomic

    genomes = load_genomes(args.genomes)
    check_writable(args.out, (".npz",))
    check_angles(args.angles, len(genomes))
    target = resolve_target(args.target)
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
    from linkevo.sim.linkage.linkage_doc import DocumentError, from_document
    from linkevo.workers.plots.linkage import SUFFIXES, draw_linkage
    from linkevo.workers.store.artifacts import read_document

    check_writable(args.out, SUFFIXES)
    check_angles(args.angles)
    source = args.source
    if source.endswith(".json"):
        path = Path(source)
        try:
            genome, mode = from_document(read_document(path))
        except DocumentError as exc:
            raise DocumentError(f"cannot load linkage document {source!r}: {exc}") from exc
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
