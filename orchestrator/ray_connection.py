"""Provides the driver's Ray connection: a local instance or a cluster, and the warm-up."""

from __future__ import annotations

import logging
import os
import signal
import threading

from linkevo.orchestrator.reservation import Cluster

LOCAL_OBJECT_STORE_BYTES = 512 * 1024**2
"""Object store of a Ray instance the driver starts itself: the trial objects are small."""


def warm_kernels() -> None:
    """Compiles (or loads) the numba simulation kernel once in the driver, so that its
    on-disk cache is written before the evaluator actors start instead of every new actor
    compiling it at the same time."""
    import numpy as np

    from linkevo.sim import evaluate, random_genomes

    evaluate(random_genomes(np.random.default_rng(0), 2))


def uses_local_ray(address: str | None) -> bool:
    """Returns True when the driver starts its own Ray instance (no address, no RAY_ADDRESS)."""
    return not (address or os.environ.get("RAY_ADDRESS"))


def dry_run_cluster(address: str | None) -> Cluster:
    """Returns the cluster a grid would run on: this machine for a local instance (nothing
    starts), else the running cluster's CPUs (joined, read, left)."""
    if uses_local_ray(address):
        return Cluster.this_machine()
    import ray

    started = connect_ray(address, Cluster.this_machine())
    try:
        return Cluster.of_ray()
    finally:
        if started:
            ray.shutdown()


def connect_ray(address: str | None, cluster: Cluster) -> bool:
    """Connects to Ray; returns True when this call started (and must stop) it.

    An explicit address or RAY_ADDRESS joins that cluster; otherwise a new local
    instance starts with `cluster`'s CPUs (a running `ray start` cluster is joined only
    with `--address auto`).
    """
    import ray

    if ray.is_initialized():
        return False
    in_main = threading.current_thread() is threading.main_thread()
    before = signal.getsignal(signal.SIGTERM) if in_main else None
    if not uses_local_ray(address):
        ray.init(address=address)
    else:
        ray.init(
            address="local",
            num_cpus=int(cluster.total_cpus),
            include_dashboard=False,
            object_store_memory=LOCAL_OBJECT_STORE_BYTES,
            logging_level=logging.WARNING,  # not "Started a local Ray instance."
        )
    if in_main:
        # ray.init installs SIGTERM handlers (a native one that dumps a stack, a Python
        # one that exits); give the signal back to the handler this process had
        # (`signals_stop_the_grid` installs the grid's own around the fan-out).
        signal.signal(signal.SIGTERM, before)
    return True
