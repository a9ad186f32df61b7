"""Times one MAP-AU trial at the study's budget, split into training and evaluation.

Runs the trial loop's ask -> evaluate -> tell cycle in-process (no recording) while a
whole batch fits in the evaluation budget (as `workers.trial.run_trial` does), then
times, on the trial's last training set (same paths, batch size, learning rate and batch
order), the compiled CPU loop the trial used, the same loop compiled with reassociated
sums and fused multiply-adds (the build before training was made CPU-independent), the
hand-written torch loop (the GPU path, and the CPU loop before the compiled one) and the
plain torch.nn + autograd + torch.optim loop (`tests/helpers/aurora_reference.py`, the
tests' oracle); and the compiled encoder against torch's on the same paths.

    .venv/bin/python benchmarks/aurora_trial.py                      # the paper's schedule
    .venv/bin/python benchmarks/aurora_trial.py --initial-epochs 300 --retrain-epochs 100
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import types
from dataclasses import fields
from pathlib import Path

import numba
import numpy as np
import torch

from linkevo.algorithms import aurora_kernel, aurora_model
from linkevo.algorithms.aurora import AuroraMapElites, AuroraSettings
from linkevo.algorithms.aurora_model import PathAutoencoder
from linkevo.algorithms.aurora_paths import valid_rows
from linkevo.sim import evaluate, random_genomes
from linkevo.sim.study import STUDY_EVALUATIONS

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the tests' oracle
from tests.helpers.aurora_reference import reference_module, train_reference


def parse_args() -> argparse.Namespace:
    """Returns the command line: budget, seed, and any `AuroraSettings` field."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--evaluations", type=int, default=STUDY_EVALUATIONS)
    parser.add_argument("--batch-size", type=int, default=5000)
    parser.add_argument("--fitness", default="Fp")
    parser.add_argument("--mode", default="paper")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--compare-epochs", type=int, default=3, help="epochs timed per loop")
    parser.add_argument("--json", help="also write the summary to this file")
    for f in fields(AuroraSettings):
        parser.add_argument(f"--{f.name.replace('_', '-')}", type=type(f.default), default=None)
    return parser.parse_args()


def fast_math_epoch():
    """Returns `aurora_kernel.train_epoch` compiled as it was before training was made
    CPU-independent: with reassociated sums and fused multiply-adds."""
    flags = {"fastmath": {"contract", "reassoc"}, "error_model": "numpy"}
    helper = {**flags, "_nrt": False, "forceinline": True, **aurora_kernel.NOALIAS}
    scope = dict(vars(aurora_kernel))  # the copies call each other through this namespace
    for name in ("multiply_add", "forward", "input_gradient", "adagrad_layer"):
        code = getattr(aurora_kernel, name).py_func.__code__
        scope[name] = numba.njit(**helper)(types.FunctionType(code, scope, name))
    code = aurora_kernel.train_epoch.py_func.__code__
    return numba.njit(**flags)(types.FunctionType(code, scope, "train_epoch"))


def compare_loops(
    paths: np.ndarray, settings: AuroraSettings, epochs: int, seed: int
) -> dict[str, float]:
    """Returns milliseconds per Adagrad step of each loop on `paths` (N, 80), and ratios.

    Each loop first runs one untimed epoch (compilation and torch's first-call set-up).
    """
    common = {"batch_size": settings.ae_batch_size, "learning_rate": settings.learning_rate}
    steps = epochs * -(-paths.shape[0] // settings.ae_batch_size)
    models = {
        name: PathAutoencoder(
            n_inputs=paths.shape[1],
            seed=seed,
            device="cpu",
            threads=settings.threads,
            loop="torch" if name == "torch" else "compiled",
        )
        for name in ("compiled", "fast_math", "torch")
    }
    plain = reference_module(models["torch"].state_dict())
    kernels = {"compiled": aurora_model.train_epoch, "fast_math": fast_math_epoch()}
    timed = {}
    for name, model in models.items():
        aurora_model.train_epoch = kernels.get(name, kernels["compiled"])
        model.train(paths, epochs=1, seed=seed, **common)
        started = time.perf_counter()
        model.train(paths, epochs=epochs, seed=seed, **common)
        timed[name] = 1e3 * (time.perf_counter() - started) / steps
    aurora_model.train_epoch = kernels["compiled"]
    encoder, reference = models["compiled"], models["torch"]
    reference.load_state_dict(encoder.state_dict())
    encoded = {}
    for name, model in (("compiled", encoder), ("torch", reference)):
        model._compiled = name == "compiled"  # the same weights, either encoder
        model.encode(paths[:64])
        started = time.perf_counter()
        for _ in range(epochs):
            model.encode(paths)
        encoded[name] = 1e3 * (time.perf_counter() - started) / epochs / len(paths) * 10_000
    train_reference(plain, paths, epochs=1, seed=seed, threads=settings.threads, **common)
    started = time.perf_counter()
    train_reference(plain, paths, epochs=epochs, seed=seed, threads=settings.threads, **common)
    timed["plain"] = 1e3 * (time.perf_counter() - started) / steps
    return {
        "compiled_ms_per_step": timed["compiled"],
        "fast_math_ms_per_step": timed["fast_math"],
        "cost_of_cpu_independence": timed["compiled"] / timed["fast_math"],
        "encode_ms_per_10k_compiled": encoded["compiled"],
        "encode_ms_per_10k_torch": encoded["torch"],
        "torch_ms_per_step": timed["torch"],
        "plain_ms_per_step": timed["plain"],
        "speedup_vs_torch": timed["torch"] / timed["compiled"],
        "speedup_vs_plain": timed["plain"] / timed["compiled"],
    }


def main() -> None:
    """Runs the trial and prints the split, the outcome and the loop comparison."""
    args = parse_args()
    options = {
        f.name: getattr(args, f.name)
        for f in fields(AuroraSettings)
        if getattr(args, f.name) is not None
    }
    optimizer = AuroraMapElites(
        fitness=args.fitness, batch_size=args.batch_size, mode=args.mode, seed=args.seed, **options
    )
    print("settings:", json.dumps(optimizer.settings()["aurora"]))
    print(f"torch {torch.__version__}, device {optimizer.encoder.device}")
    evaluate(random_genomes(np.random.default_rng(0), 8), args.fitness, args.mode)  # compiles
    settings = optimizer.aurora
    evaluate_s = 0.0
    steps = 0
    started = time.perf_counter()
    while optimizer.evaluations + args.batch_size <= args.evaluations:  # as run_trial
        genomes = optimizer.ask()
        t0 = time.perf_counter()
        evaluation = evaluate(genomes, args.fitness, args.mode)
        evaluate_s += time.perf_counter() - t0
        optimizer.tell(genomes, evaluation)
        m = optimizer.metrics()
        if m["train_paths"] > 0:
            epochs = (
                settings.initial_epochs if optimizer.trainings == 1 else settings.retrain_epochs
            )
            steps += epochs * -(-int(m["train_paths"]) // settings.ae_batch_size)
            print(
                f"iter {int(m['iteration']):4d}  trained on {int(m['train_paths']):5d} paths"
                f"  recon {m['recon_loss']:.4f}  dropped {m['elites_dropped']:.0f}"
                f"  coverage {m['coverage']:.4f}  best {m['best_loss']:.3f}"
                f"  t={time.perf_counter() - started:.0f}s",
                flush=True,
            )
    total_s = time.perf_counter() - started
    m = optimizer.metrics()
    elites = optimizer.archive.elites
    assert elites is not None
    valid = valid_rows(elites.error)
    summary = {
        "evaluations": optimizer.evaluations,
        "iterations": optimizer.iteration,
        "trainings": optimizer.trainings,
        "total_s": total_s,
        "training_s": optimizer.training_seconds,
        "evaluation_s": evaluate_s,
        "other_s": total_s - optimizer.training_seconds - evaluate_s,
        "training_steps": steps,
        "ms_per_step": 1e3 * optimizer.training_seconds / max(steps, 1),
        "coverage": m["coverage"],
        "valid_elites": int(valid.size),
        "best_loss": m["best_loss"],
        "qd_score": m["qd_score"],
    }
    paths = optimizer.paths_of(elites.foot_x[valid], elites.foot_y[valid])
    summary |= compare_loops(paths, optimizer.aurora, args.compare_epochs, args.seed)
    for key, value in summary.items():
        print(f"{key:>14}: {value:.4g}" if isinstance(value, float) else f"{key:>14}: {value}")
    print(
        f"ratio: the compiled loop takes {summary['speedup_vs_torch']:.2f}x fewer seconds per "
        f"step than the torch loop and {summary['speedup_vs_plain']:.2f}x fewer than "
        f"torch.nn+autograd+torch.optim ({paths.shape[0]} paths, batch "
        f"{optimizer.aurora.ae_batch_size}, one thread); CPU-independent sums cost "
        f"{summary['cost_of_cpu_independence']:.2f}x the reassociated, fused build's time"
    )
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(summary | {"settings": optimizer.settings()["aurora"]}, handle, indent=1)


if __name__ == "__main__":
    main()
