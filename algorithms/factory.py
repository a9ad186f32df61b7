"""Provides make_optimizer: one constructor for every approach of the study."""

from __future__ import annotations

from linkevo.algorithms.ea import EvolutionaryAlgorithm
from linkevo.algorithms.map_elites import MapElites
from linkevo.algorithms.nsga2 import NSGA2
from linkevo.algorithms.optimizer import Optimizer
from linkevo.algorithms.random_sampling import RandomSampling
from linkevo.sim.linkage.descriptors import COVERAGE_SPACES, check_coverage_space
from linkevo.sim.study import APPROACHES, DEFAULT_ANGLES, MULTI_OBJECTIVE, evaluated_fitness

_OPTIONS: dict[str, tuple[str, ...]] = {
    "EA": ("coverage_space", "initial_sigma"),
    "NSGA2": ("coverage_space", "initial_sigma"),
    "RANDOM": ("coverage_space", "initial_sigma"),
    "MAP-WH": ("initial_sigma",),
    "MAP-LIS": ("initial_sigma",),
    "MAP-ST": ("initial_sigma",),
}


def eval_fitness(approach: str, fitness: str) -> str:
    """Returns the `sim.linkage.evaluating` fitness an approach needs: "Fp2"/"Fsl2" for NSGA2."""
    return evaluated_fitness(fitness, approach in MULTI_OBJECTIVE)


def check_options(approach: str, options: dict[str, object]) -> None:
    """Raises ValueError, naming the option and the allowed ones, for options `approach`
    would refuse; MAP-AU's are checked without building its autoencoder (no torch, unless
    they ask for a GPU by name)."""
    from linkevo.algorithms.mutation import check_initial_sigma

    check_initial_sigma(options.get("initial_sigma"))
    if approach == "MAP-AU":
        from linkevo.algorithms.aurora_settings import AuroraSettings

        settings = AuroraSettings.from_options(
            {k: v for k, v in options.items() if k != "initial_sigma"}
        )
        if settings.device == "cuda":
            settings.resolved_device()
        return
    if approach not in _OPTIONS:
        raise ValueError(f"unknown approach {approach!r}; allowed: {', '.join(APPROACHES)}")
    unknown = sorted(set(options) - set(_OPTIONS[approach]))
    if unknown:
        raise ValueError(
            f"unknown option(s) {', '.join(map(repr, unknown))} for {approach}; "
            f"allowed: {', '.join(_OPTIONS[approach])}"
        )
    check_coverage_space(options.get("coverage_space", COVERAGE_SPACES[0]))


def make_optimizer(
    approach: str,
    *,
    fitness: str,
    batch_size: int,
    mode: str,
    seed: int,
    n_angles: int = DEFAULT_ANGLES,
    **options: object,
) -> Optimizer:
    """Returns a fresh optimizer for `approach`.

    Args:
        approach: one of `APPROACHES`.
        fitness: "Fp" or "Fsl" (NSGA-II evaluates "Fp2"/"Fsl2"; see `eval_fitness`).
        batch_size: genomes per ask, B (also the initial population and EA/NSGA-II
            population size).
        mode: "paper" or "legacy".
        seed: seed of the optimizer's random stream.
        n_angles: crank angles per evaluation.
        **options: approach-specific settings: `initial_sigma` (all but MAP-AU),
            `coverage_space` (EA, NSGA2, RANDOM); MAP-AU passes all of them to
            `AuroraMapElites`.

    Raises:
        ValueError: naming an unknown approach or option, or a bad setting.
    """
    common = {
        "fitness": fitness,
        "batch_size": batch_size,
        "mode": mode,
        "seed": seed,
        "n_angles": n_angles,
    }
    if approach == "MAP-AU":
        from linkevo.algorithms.aurora import AuroraMapElites

        return AuroraMapElites(**common, **options)
    check_options(approach, options)
    if approach == "EA":
        return EvolutionaryAlgorithm(**common, **options)
    if approach == "NSGA2":
        return NSGA2(**common, **options)
    if approach == "RANDOM":
        return RandomSampling(**common, **options)
    return MapElites(approach=approach, **common, **options)
