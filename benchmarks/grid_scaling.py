"""Benchmarks the grid machinery: evaluator throughput, MLflow overhead, the quick preset.

Run from the repository root:

    .venv/bin/python benchmarks/grid_scaling.py [--skip-quick]
    .venv/bin/python benchmarks/grid_scaling.py --only-quick --against ../other-checkout --rounds 3

Prints three measurements:
1. one trial's evaluation throughput (batch 5,000) in process (`LocalEvaluator`, 1 and 2
   numba threads, how a trial evaluates by default) and through 1 and 2 one-CPU evaluator
   actors, with the plain per-linkage reference `sim.linkage.reference.evaluate_reference`
   measured in the same run as the baseline;
2. the MLflow overhead per iteration at batch 5,000: the same EA trial through
   `workers.trial.run_trial` in process, untracked and with an MLflow recorder on a fresh
   sqlite store (alternating, best of 11), split into the per-iteration loop and the
   once-per-trial part;
3. the wall time of `linkevo grid configs/quick.toml` on a fresh store and the grid's
   overhead per trial (unless skipped); with `--against TREE`, the same grid run by
   another checkout's code in turn with this one's, and the median ratio.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np
import ray
from trees import tree_env  # benchmarks/trees.py, beside this script

from linkevo.orchestrator.launch_checks import trial_specs
from linkevo.sim import named_target, random_genomes
from linkevo.sim.linkage.reference import evaluate_reference
from linkevo.workers.evaluators import LocalEvaluator
from linkevo.workers.ray_evaluator import ActorPoolEvaluator
from linkevo.workers.recorders import NullRecorder
from linkevo.workers.store.mlflow_recorder import MlflowRecorder
from linkevo.workers.store.runs import RunStore
from linkevo.workers.store.tracking import ensure_experiment
from linkevo.workers.trial import run_trial
from linkevo.workers.trial_spec import TrialSpec

BATCH = 5000
REPEATS = 40
REFERENCE_GENOMES = 100
REPO = Path(__file__).resolve().parent.parent


def actor_scaling(genomes: np.ndarray) -> None:
    """Prints evaluations per second through 1 and 2 actors and the two baselines.

    The four set-ups (1 and 2 numba threads in process, 1 and 2 actors) take turns call by
    call, REPEATS rounds, so drifting load on a shared machine reaches all of them alike;
    each keeps its best call, and the median of the per-round ratios is printed too.
    """
    local = LocalEvaluator("Fp", "paper")

    def in_process(threads: int):
        def call():
            numba.set_num_threads(threads)
            local(genomes)

        return call

    pools = {
        k: ActorPoolEvaluator.start(
            n_actors=k, cpus_per_actor=1, fitness="Fp", mode="paper", target="D16", n_angles=40
        )
        for k in (1, 2)
    }
    setups = {
        "thread1": in_process(1),
        "thread2": in_process(2),
        "actor1": lambda: pools[1](genomes),
        "actor2": lambda: pools[2](genomes),
    }
    seconds: dict[str, list[float]] = {name: [] for name in setups}
    try:
        for call in setups.values():
            call()  # warm-up: channels, batch files, buffers
        for _ in range(REPEATS):
            for name, call in setups.items():
                start = time.perf_counter()
                call()
                seconds[name].append(time.perf_counter() - start)
    finally:
        for pool in pools.values():
            pool.close()
        numba.set_num_threads(1)
    rate = {name: len(genomes) / min(times) for name, times in seconds.items()}

    def ratio(one: str, two: str) -> str:
        rounds = np.median(np.divide(seconds[one], seconds[two]))
        return f"{rate[two] / rate[one]:.2f}x (median of rounds {rounds:.2f}x)"

    few = genomes[:REFERENCE_GENOMES]
    start = time.perf_counter()
    evaluate_reference(few, "Fp", target=named_target("D16"))
    reference_rate = len(few) / (time.perf_counter() - start)
    print(f"## 1. evaluation throughput, batch {len(genomes)} (best of {REPEATS}, alternating)")
    print(f"plain reference (sim.linkage.reference, one at a time): {reference_rate:12,.0f} eval/s")
    print(f"in-process LocalEvaluator, 1 numba thread:           {rate['thread1']:12,.0f} eval/s")
    print(f"in-process LocalEvaluator, 2 numba threads:          {rate['thread2']:12,.0f} eval/s")
    print(f"1 evaluator actor (1 CPU):                           {rate['actor1']:12,.0f} eval/s")
    print(f"2 evaluator actors (1 CPU each):                     {rate['actor2']:12,.0f} eval/s")
    print(f"speed-up 2 vs 1 actor: {ratio('actor1', 'actor2')}")
    print(
        f"speed-up 2 vs 1 numba thread in process: {ratio('thread1', 'thread2')} "
        "(what this machine's two cores give the kernel without Ray)"
    )
    print(f"2 actors vs plain reference: {rate['actor2'] / reference_rate:,.0f}x")


LOOP_PHASES = ("ask", "evaluate", "tell", "record", "checkpoint")
"""The per-iteration phases of `run_trial` (TrialResult.timings); the rest is per trial."""


def tracking_overhead(work: Path, iterations: int, rounds: int = 11) -> None:
    """Prints the per-iteration cost of MLflow tracking in a trial evaluating in process.

    The untracked trial and the tracked one alternate `rounds` times;
    for each the round with the shortest loop is kept, so a load spike on a shared machine
    does not land on one side only. The loop phases (ask, evaluate, tell, record,
    checkpoint) are what every iteration costs; the end of the trial (final artefacts and
    logging them to MLflow) is paid once per trial and reported on its own.
    """
    from mlflow.tracking import MlflowClient

    numba.set_num_threads(1)
    spec = TrialSpec(
        approach="EA", fitness="Fp", evaluations=BATCH * iterations, batch_size=BATCH, seed=1
    )
    uri = f"sqlite:///{work / 'store' / 'mlflow.db'}"
    experiment_id = ensure_experiment(uri, "bench")
    client = MlflowClient(uri)
    local, tracked = [], []

    def timed(evaluator, recorder, folder: str) -> tuple[float, dict[str, float], float]:
        start = time.perf_counter()
        result = run_trial(spec, evaluator, recorder, work / folder)
        total = time.perf_counter() - start
        loop = sum(result.timings[phase] for phase in LOOP_PHASES)
        return loop, result.timings, total - loop

    for i in range(rounds):
        local.append(timed(LocalEvaluator("Fp", "paper"), NullRecorder(), f"local{i}"))
        run_id = client.create_run(experiment_id, run_name=f"bench{i}").info.run_id
        tracked.append(
            timed(LocalEvaluator("Fp", "paper"), MlflowRecorder(client, run_id), f"tracked{i}")
        )
        client.set_terminated(run_id)
    (local_loop, local_phases, local_end) = min(local, key=lambda r: r[0])
    (tracked_loop, tracked_phases, tracked_end) = min(tracked, key=lambda r: r[0])
    per_iteration = (tracked_loop - local_loop) / iterations
    print(f"\n## 2. MLflow overhead, EA trial of {iterations} iterations x {BATCH}")
    print(f"(best loop of {rounds} alternating rounds)")
    print(f"{'ms per iteration':<28}" + "".join(f"{p:>11}" for p in (*LOOP_PHASES, "loop")))
    for name, loop, phases in (
        ("in-process, untracked", local_loop, local_phases),
        ("in-process + MLflow (sqlite)", tracked_loop, tracked_phases),
    ):
        cells = [phases[p] / iterations * 1000 for p in LOOP_PHASES] + [loop / iterations * 1000]
        print(f"{name:<28}" + "".join(f"{c:>11.1f}" for c in cells))
    print(
        f"overhead: {per_iteration * 1000:.1f} ms per iteration = "
        f"{100 * per_iteration * iterations / tracked_loop:.1f} % of the tracked iteration "
        "(target <= 5 %)"
    )
    print(
        f"once per trial (set-up, final artefacts, metric flush, artefact upload): "
        f"{local_end:.2f} s untracked, {tracked_end:.2f} s tracked"
    )
    study = 145
    share = (per_iteration * study + tracked_end - local_end) / (
        tracked_loop / iterations * study + tracked_end
    )
    print(f"whole-trial overhead at the study's {study} iterations: {100 * share:.1f} %")


def quick_grid_seconds(tree: Path, store: Path, work: Path) -> float:
    """Runs `linkevo grid configs/quick.toml` of the code in `tree` on a fresh `store`
    (`benchmarks.trees.tree_env`); returns its wall time in seconds."""
    command = [
        sys.executable,
        "-m",
        "linkevo.orchestrator",
        "grid",
        "configs/quick.toml",
        "--tracking-uri",
        str(store),
        "--no-progress",
    ]
    env = tree_env(tree, work)
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, cwd=tree, env=env, check=False)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        print(done.stderr[-2000:])
        raise SystemExit(f"the quick grid of {tree} failed (exit {done.returncode})")
    return seconds


def quick_preset(work: Path, against: Path | None, rounds: int) -> None:
    """Prints the quick preset's wall time on a fresh store and its overhead per trial;
    with `against`, the same grid of that tree's code too, the two taking turns.

    The overhead is what a trial costs a slot in the grid beyond its own trial loop: the
    slot-seconds of the fan-out (first trial start to last trial end, times the trials in
    flight) per trial, less the mean loop time (ask, evaluate, tell, record, checkpoint)
    of the same trials run in process without tracking. It holds the Ray task, the MLflow
    run, the final files and drawings, and their upload.
    """

    from linkevo.orchestrator import config
    from linkevo.orchestrator.grid import Grid
    from linkevo.orchestrator.reservation import Cluster, Reservation
    from linkevo.workers.store import run_layout as layout

    print("\n## 3. quick preset (120 trials)")
    trees = {"this tree": REPO} | ({f"{against}": against} if against else {})
    times: dict[str, list[float]] = {name: [] for name in trees}
    for _ in range(rounds):
        for name, tree in trees.items():
            store = work / f"store-{len(times[name])}-{abs(hash(name))}"
            times[name].append(quick_grid_seconds(tree, store, work))
    for name, values in times.items():
        shown = ", ".join(f"{v:.1f}" for v in values)
        print(
            f"wall time of linkevo grid configs/quick.toml, {name}: {shown} s "
            f"(median {np.median(values):.1f} s)"
        )
    if against:
        ratios = [a / b for a, b in zip(*times.values(), strict=True)]
        print(f"this tree / {against}: median ratio {np.median(ratios):.3f} over {rounds} pair(s)")

    preset = REPO / "configs" / "quick.toml"
    store = work / f"store-0-{abs(hash('this tree'))}"
    grid = Grid.from_config(config.load(preset))
    runs = RunStore(f"sqlite:///{store / 'mlflow.db'}", grid.config.experiment).search(
        layout.where(layout.TRIAL)
    )
    fan_out = (max(r.info.end_time for r in runs) - min(r.info.start_time for r in runs)) / 1e3
    slots = Reservation.plan(grid.config, len(grid.cells), Cluster.this_machine()).concurrent
    specs = trial_specs(grid)
    numba.set_num_threads(1)
    loops = []
    for key, spec in specs.items():
        result = run_trial(
            spec,
            LocalEvaluator(spec.eval_fitness, spec.mode),
            NullRecorder(),
            work / "in-process" / key.replace("/", "-"),
        )
        loops.append(sum(result.timings[phase] for phase in LOOP_PHASES))
    per_slot = fan_out * slots / len(runs)
    loop = float(np.mean(loops))
    print(
        f"fan-out {fan_out:.1f} s for {len(runs)} trials, {slots} at once: {per_slot:.2f} "
        f"slot-seconds per trial; the trial loop in process {loop:.2f} s"
    )
    print(f"grid overhead per trial: {per_slot - loop:.2f} s (target <= 0.5 s)")


def main() -> int:
    """Runs the three measurements."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=BATCH, help="batch of section 1")
    parser.add_argument("--iterations", type=int, default=30, help="iterations of section 2")
    parser.add_argument("--skip-quick", action="store_true")
    parser.add_argument("--only-quick", action="store_true", help="section 3 alone")
    parser.add_argument("--against", type=Path, help="another checkout's quick grid too")
    parser.add_argument("--rounds", type=int, default=1, help="quick grids of each tree")
    args = parser.parse_args()
    if args.only_quick:
        with tempfile.TemporaryDirectory() as tmp:
            quick_preset(Path(tmp), args.against, args.rounds)
        return 0
    genomes = random_genomes(np.random.default_rng(0), args.batch)
    # Three CPUs on two cores: section 1's 1-actor and 2-actor pools live side by side so
    # their calls can alternate; only one of them works at any time.
    ray.init(
        address="local", num_cpus=3, object_store_memory=300 * 1024**2, include_dashboard=False
    )
    try:
        actor_scaling(genomes)
        with tempfile.TemporaryDirectory() as tmp:
            tracking_overhead(Path(tmp), args.iterations)
    finally:
        ray.shutdown()
    if not args.skip_quick:
        with tempfile.TemporaryDirectory() as tmp:
            quick_preset(Path(tmp), args.against, args.rounds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
