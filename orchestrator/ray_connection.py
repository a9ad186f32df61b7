"""Provides the driver's Ray connection: a local instance or a cluster, and the warm-up."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
import uuid

from linkevo.orchestrator.reservation import Cluster

LOCAL_OBJECT_STORE_BYTES = 512 * 1024**2
"""Object store of a Ray instance the driver starts itself: the trial objects are small."""
LOOPBACK_ENV = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
"""Ray's switch between a single-machine instance on the loopback address (its default on
macOS and Windows) and a cluster node on the machine's network address (its default on
Linux). Ray 2.60 ignores `ray.init(_node_ip_address="127.0.0.1")` for a local instance
and binds its gRPC servers to every interface; with this switch off, the GCS, raylet,
workers and agents listen on 127.0.0.1 only."""
_reaper: subprocess.Popen | None = None
"""This process's reaper (`orchestrator.reaper`), once a local instance was started."""


def _loopback_only(local: bool) -> None:
    """Sets Ray's loopback switch (`LOOPBACK_ENV`) for what this process starts or joins:
    the environment for the processes Ray spawns, and Ray's own reading of it in this
    process, which Ray takes once at import (so a process that ran a local grid can
    still join a cluster afterwards)."""
    from ray._private import ray_constants

    if local:
        os.environ[LOOPBACK_ENV] = "0"
    else:
        os.environ.pop(LOOPBACK_ENV, None)
    ray_constants.ENABLE_RAY_CLUSTER = not local


_reaper_token = uuid.uuid4().hex
"""What marks this process's local Ray processes for its reaper (`reaper.SESSION_ENV`)."""


def _start_reaper() -> None:
    """Starts, once per process, `orchestrator.reaper`: it stops what is left of this
    process's local Ray instance when this process ends, however it ends."""
    global _reaper
    if _reaper is None:
        _reaper = subprocess.Popen(
            [sys.executable, "-m", "linkevo.orchestrator.reaper", _reaper_token],
            stdin=subprocess.PIPE,
            start_new_session=True,
        )


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
    local = uses_local_ray(address)
    _loopback_only(local)
    if not local:
        ray.init(address=address)
    else:
        from linkevo.orchestrator.reaper import SESSION_ENV

        _start_reaper()
        # Ray's processes (and the workers its raylet starts later) inherit the reaper's
        # token from this environment; this process's later children do not.
        os.environ[SESSION_ENV] = _reaper_token
        try:
            ray.init(
                address="local",
                num_cpus=int(cluster.total_cpus),
                include_dashboard=False,
                object_store_memory=LOCAL_OBJECT_STORE_BYTES,
                logging_level=logging.WARNING,  # not "Started a local Ray instance."
            )
        finally:
            os.environ.pop(SESSION_ENV, None)
    if in_main:
        # ray.init installs SIGTERM handlers (a native one that dumps a stack, a Python
        # one that exits); give the signal back to the handler this process had
        # (`signals_stop_the_grid` installs the grid's own around the fan-out).
        signal.signal(signal.SIGTERM, before)
    return True
