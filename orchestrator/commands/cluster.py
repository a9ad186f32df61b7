"""Provides `linkevo cluster up|down|env`: a local PostgreSQL + MLflow server + multi-node Ray
cluster, started the way a real cluster is (`orchestrator.local_cluster`)."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from linkevo.orchestrator.cli import CliError

DEFAULT_DIR = Path("runs/cluster")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the `cluster` subcommand and its actions."""
    parser = subparsers.add_parser(
        "cluster",
        help="start or stop a local PostgreSQL + MLflow server + multi-node Ray cluster",
        description=(
            "up: PostgreSQL (loopback, throwaway data directory), an MLflow server on it with "
            "proxied artefacts, a Ray head and N worker nodes, each started with `ray start` "
            "as its own processes; prints what to pass to `linkevo grid`. down: stops all of "
            "it and leaves no process or port behind. env: prints the Ray token variables a "
            "driver needs, for `eval`."
        ),
    )
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    start = actions.add_parser("up", help="start the cluster")
    start.add_argument("--workers", type=int, default=2, help="Ray worker nodes")
    start.add_argument("--cpus-per-worker", type=int, default=1, help="CPUs of each worker node")
    start.add_argument("--head-cpus", type=int, default=0, help="CPUs of the head node")
    start.add_argument("--object-store-mb", type=int, default=100, help="object store per node")
    start.add_argument("--mlflow-workers", type=int, default=2, help="MLflow server workers")
    for name in ("postgres", "mlflow", "ray"):
        start.add_argument(f"--{name}-port", type=int, default=0, help="0 takes a free port")
    for action in (start, actions.add_parser("down", help="stop the cluster")):
        action.add_argument("--dir", type=Path, default=DEFAULT_DIR, help="the cluster's folder")
    env = actions.add_parser("env", help="print the variables a Ray driver needs")
    env.add_argument("--dir", type=Path, default=DEFAULT_DIR, help="the cluster's folder")
    parser.set_defaults(func=handler)


def handler(args: argparse.Namespace) -> int:
    """Runs `linkevo cluster ACTION`."""
    from linkevo.orchestrator import local_cluster as lc

    if args.action == "up":
        settings = lc.ClusterSettings(
            dir=args.dir,
            workers=args.workers,
            cpus_per_worker=args.cpus_per_worker,
            head_cpus=args.head_cpus,
            object_store_mb=args.object_store_mb,
            mlflow_workers=args.mlflow_workers,
            postgres_port=args.postgres_port,
            mlflow_port=args.mlflow_port,
            ray_port=args.ray_port,
        )
        state = lc.up(settings)
        cpus = sum(n.cpus for n in state.nodes)
        print(f"cluster up in {state.dir}: {len(state.workers)} worker nodes, {cpus} CPUs")
        print(f"  PostgreSQL   {state.database_uri}")
        print(f"  MLflow       {state.tracking_uri}   (artefacts in {state.dir}/artifacts)")
        print(f"  Ray head     {state.address}")
        print("Run a grid on it:")
        print(f'  eval "$(linkevo cluster env --dir {shlex.quote(state.dir)})"')
        print(
            f"  linkevo grid configs/quick.toml --address {state.address} "
            f"--tracking-uri {state.tracking_uri}"
        )
        print(f"Stop it with: linkevo cluster down --dir {shlex.quote(state.dir)}")
        return 0
    if args.action == "down":
        stopped = lc.down(args.dir)
        print(f"stopped: {', '.join(stopped)}" if stopped else f"no cluster in {args.dir}")
        return 0
    state = lc.ClusterState.load(args.dir)
    if state is None:
        raise CliError(f"no cluster in {args.dir}; start one with: linkevo cluster up")
    for name, value in state.env.items():
        print(f"export {name}={shlex.quote(value)}")
    return 0
