"""Provides Reservation: what one trial reserves on the cluster at hand, and how many run."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace

from linkevo.orchestrator.config import ConfigError, GridConfig


@dataclass(frozen=True)
class Cluster:
    """The CPUs a grid can use.

    Attributes:
        total_cpus: CPUs over every alive node.
        largest_node_cpus: CPUs of the largest node (one trial's bundles share a node).
        local: True for the Ray instance the driver starts on this machine.
    """

    total_cpus: float
    largest_node_cpus: float
    local: bool

    @staticmethod
    def this_machine() -> Cluster:
        """Returns the CPUs this process may run on: what a local Ray instance is given."""
        cpus = float(len(os.sched_getaffinity(0)))
        return Cluster(total_cpus=cpus, largest_node_cpus=cpus, local=True)

    @staticmethod
    def of_ray() -> Cluster:
        """Returns the CPUs of the Ray cluster this process is connected to."""
        import ray

        nodes = [n["Resources"].get("CPU", 0.0) for n in ray.nodes() if n.get("Alive")]
        return Cluster(
            total_cpus=float(sum(nodes)),
            largest_node_cpus=float(max(nodes, default=0.0)),
            local=False,
        )


@dataclass(frozen=True)
class Reservation:
    """One trial's Ray reservation and the number of trials in flight.

    Attributes:
        evaluators: evaluator actors per trial (K); 0: the trial task evaluates itself.
        cpus_per_evaluator: CPUs each actor reserves.
        trial_cpus: CPUs the trial task reserves.
        threads: numba threads the trial task evaluates with (K = 0).
        concurrent: trials in flight at once.
    """

    evaluators: int
    cpus_per_evaluator: float
    trial_cpus: float
    threads: int
    concurrent: int

    @property
    def per_trial_cpus(self) -> float:
        """CPUs one trial reserves: its task's plus its evaluators'."""
        return self.trial_cpus + self.evaluators * self.cpus_per_evaluator

    def bundles(self) -> list[dict[str, float]]:
        """Returns a trial's placement-group bundles: the trial task's own (if it reserves
        CPUs), then one per evaluator actor."""
        own = [{"CPU": self.trial_cpus}] if self.trial_cpus > 0 else []
        return own + [{"CPU": self.cpus_per_evaluator}] * self.evaluators

    def describe(self) -> str:
        """Returns the reservation in words."""
        if self.evaluators == 0:
            how = f"the trial task evaluates with {self.threads} numba thread(s)"
        else:
            how = (
                f"{self.evaluators} evaluator actor(s) x {self.cpus_per_evaluator:g} CPU + "
                f"{self.trial_cpus:g} for the trial loop"
            )
        return (
            f"each trial reserves {self.per_trial_cpus:g} CPU ({how}); "
            f"{self.concurrent} trial(s) at once"
        )

    @staticmethod
    def plan(config: GridConfig, n_trials: int, cluster: Cluster) -> Reservation:
        """Returns the reservation of `n_trials` trials of `config` on `cluster`.

        With `evaluators_per_trial = 0` and `trial_cpus = "auto"` the cluster's CPUs are
        shared out: each trial gets floor(total / n_trials) CPUs, at least 1 and at most
        the largest node's, and evaluates with that many threads. With actors,
        `trial_cpus = "auto"` is 0 (the trial loop shares the first actor's CPU).

        Raises:
            ConfigError: when one trial's reservation cannot fit the cluster, naming the
                keys, the cluster's size and what would fit.
        """
        k = config.evaluators_per_trial
        largest = cluster.largest_node_cpus
        if config.trial_cpus == "auto":
            if k == 0:
                share = math.floor(cluster.total_cpus / max(n_trials, 1))
                trial_cpus = float(min(max(share, 1), max(math.floor(largest), 1)))
            else:
                trial_cpus = 0.0
        else:
            trial_cpus = float(config.trial_cpus)
        reservation = Reservation(
            evaluators=k,
            cpus_per_evaluator=float(config.cpus_per_evaluator),
            trial_cpus=trial_cpus,
            threads=max(1, math.floor(trial_cpus)),
            concurrent=1,
        )
        per_trial = reservation.per_trial_cpus
        biggest_bundle = max(reservation.cpus_per_evaluator if k else 0.0, trial_cpus)
        where = "this machine" if cluster.local else "the Ray cluster"
        if per_trial > cluster.total_cpus or biggest_bundle > largest:
            raise ConfigError(
                f"one trial reserves {per_trial:g} CPU (evaluators_per_trial={k}, "
                f"cpus_per_evaluator={config.cpus_per_evaluator:g}, trial_cpus="
                f"{config.trial_cpus!r}) but {where} has {cluster.total_cpus:g} CPU "
                f"(largest node {largest:g}); allowed: a reservation that fits, e.g. the "
                'default evaluators_per_trial = 0 with trial_cpus = "auto"'
            )
        fits = max(1, int(cluster.total_cpus // per_trial))
        concurrent = config.max_concurrent_trials or fits
        return replace(reservation, concurrent=concurrent)
