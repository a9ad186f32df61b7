"""The ask/tell optimizers: protocol, survivors, reproducibility, state dicts, views."""

from __future__ import annotations

import io

import numpy as np
import pytest

from linkevo.algorithms import MapElites, make_optimizer, scalar_loss
from linkevo.sim.linkage.descriptors import DESCRIPTOR_SPACES
from linkevo.sim.linkage.evaluating import evaluate
from linkevo.sim.linkage.evaluation import Evaluation
from linkevo.sim.linkage.genome import N_GENES
from linkevo.sim.study import APPROACHES, REPERTOIRE_APPROACHES

BUILT_IN = [a for a in APPROACHES if a != "MAP-AU"]
N_ANGLES = 4


def synthetic_evaluation(genomes: np.ndarray, n_objectives: int = 1) -> Evaluation:
    """Returns a deterministic Evaluation of genomes (N, 56) without simulating anything.

    loss: squared distance to 0.3 (over two halves of the genome for two objectives);
    descriptors: scaled genes, so every approach's grid gets spread-out values.
    """
    sq = (genomes - 0.3) ** 2
    loss = sq.sum(axis=1) if n_objectives == 1 else np.c_[sq[:, :28].sum(1), sq[:, 28:].sum(1)]
    n = genomes.shape[0]
    angles = np.linspace(0.0, 2 * np.pi, N_ANGLES, endpoint=False)
    return Evaluation(
        loss=loss,
        error=np.zeros(n, dtype=np.int64),
        angle_error=np.zeros(n),
        valid=np.ones((n, N_ANGLES), dtype=bool),
        foot=np.full(n, 5, dtype=np.int64),
        foot_x=genomes[:, :1] * np.cos(angles),
        foot_y=genomes[:, 1:2] * np.sin(angles),
        descriptors={
            "MAP-WH": genomes[:, :2] * 100.0,
            "MAP-LIS": genomes[:, 2:4] * np.array([10.0, 50.0]),
            "MAP-ST": genomes[:, 4:8] * 10.0,
        },
    )


def run(opt, iterations: int) -> list[dict[str, float]]:
    history = []
    for _ in range(iterations):
        genomes = opt.ask()
        opt.tell(genomes, synthetic_evaluation(genomes, 2 if opt.eval_fitness[-1] == "2" else 1))
        history.append(opt.metrics())
    return history


def make(approach: str, seed: int = 0, batch_size: int = 64, **options):
    return make_optimizer(
        approach, fitness="Fp", batch_size=batch_size, mode="paper", seed=seed, **options
    )


def npz_round_trip(state: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    buffer = io.BytesIO()
    np.savez(buffer, **state)
    buffer.seek(0)
    with np.load(buffer, allow_pickle=False) as data:
        return {k: data[k] for k in data.files}


@pytest.mark.parametrize("approach", BUILT_IN)
def test_first_ask_is_the_random_initial_batch(approach: str) -> None:
    opt = make(approach)
    genomes = opt.ask()
    assert genomes.shape == (64, N_GENES)
    assert genomes.min() >= 0.0 and genomes.max() < 1.0
    opt.tell(genomes, synthetic_evaluation(genomes, 2 if approach == "NSGA2" else 1))
    metrics = opt.metrics()
    assert metrics["evaluations"] == 64 and metrics["iteration"] == 1
    assert {"best_loss", "mean_loss", "coverage", "qd_score"} <= set(metrics)
    assert ("hypervolume" in metrics) == (approach == "NSGA2")


@pytest.mark.parametrize("approach", BUILT_IN)
def test_search_improves_the_best_loss(approach: str) -> None:
    history = run(make(approach, batch_size=200, initial_sigma=0.1), 15)
    assert history[-1]["best_loss"] < history[0]["best_loss"]
    assert history[-1]["evaluations"] == 15 * 200


@pytest.mark.parametrize("approach", BUILT_IN)
def test_same_seed_same_metrics_other_seed_differs(approach: str) -> None:
    a = run(make(approach, seed=3), 5)
    b = run(make(approach, seed=3), 5)
    c = run(make(approach, seed=4), 5)
    assert a == b
    assert a != c


@pytest.mark.parametrize("approach", BUILT_IN)
def test_state_dict_resumes_identically(approach: str) -> None:
    original = make(approach, seed=5)
    run(original, 3)
    state = npz_round_trip(original.state_dict())
    assert all(isinstance(v, np.ndarray) for v in state.values())
    resumed = make(approach, seed=5)
    resumed.load_state_dict(state)
    assert run(resumed, 3) == run(original, 3)
    np.testing.assert_array_equal(resumed.ask(), original.ask())


def test_load_state_dict_refuses_other_settings() -> None:
    state = make("EA", seed=1).state_dict()
    with pytest.raises(ValueError, match="seed"):
        make("EA", seed=2).load_state_dict(state)


def test_protocol_misuse_is_refused() -> None:
    opt = make("MAP-LIS")
    genomes = opt.ask()
    with pytest.raises(RuntimeError, match="ask\\(\\) called twice"):
        opt.ask()
    with pytest.raises(RuntimeError, match="between ask\\(\\) and tell\\(\\)"):
        opt.state_dict()
    with pytest.raises(ValueError, match="exactly the genomes"):
        opt.tell(genomes[::-1], synthetic_evaluation(genomes[::-1]))
    with pytest.raises(ValueError, match=r"losses of shape \(64,\) \(fitness Fp\)"):
        opt.tell(genomes, synthetic_evaluation(genomes, 2))


def test_ea_children_replace_the_population() -> None:
    opt = make("EA", batch_size=100)
    run(opt, 2)
    children = opt.ask()
    opt.tell(children, synthetic_evaluation(children))
    np.testing.assert_array_equal(opt.population.genome, children)


def test_nsga2_keeps_a_front_ordered_population_from_parents_and_children() -> None:
    opt = make("NSGA2", batch_size=100)
    run(opt, 1)
    parents = opt.population.genome.copy()
    children = opt.ask()
    opt.tell(children, synthetic_evaluation(children, 2))
    kept = opt.population.genome
    pool = np.concatenate([parents, children])
    assert all((pool == row).all(axis=1).any() for row in kept)
    view = opt.view()
    assert np.all(np.diff(view["front"]) >= 0)
    assert opt.metrics()["hypervolume"] > 0


def test_map_elites_parents_come_from_the_repertoire() -> None:
    opt = make("MAP-LIS", batch_size=100, initial_sigma=0.0)
    run(opt, 1)
    elites = opt.archive.elites.genome
    children = opt.ask()  # sigma 0 until it is perturbed: most children copy an elite
    copies = [(elites == row).all(axis=1).any() for row in children]
    assert np.mean(copies) > 0.5
    assert opt.metrics()["coverage"] == len(opt.archive) / 10_000


def test_map_elites_descriptor_hook_and_reindex() -> None:
    class FirstGenes(MapElites):
        def descriptors_of(self, genomes, evaluation):
            return genomes[:, :2] * 100.0

    opt = FirstGenes(
        approach="MAP-WH", fitness="Fp", batch_size=50, mode="paper", seed=0, n_angles=N_ANGLES
    )
    run(opt, 2)
    np.testing.assert_array_equal(opt.archive.elites.desc, opt.archive.elites.genome[:, :2] * 100)
    before = len(opt.archive)
    dropped = opt.reindex(np.zeros((before, 2)))
    assert dropped == before - 1 and len(opt.archive) == 1
    assert opt.archive.elites.loss[0] == opt.best()[1]


@pytest.mark.parametrize("approach", BUILT_IN)
def test_view_columns(approach: str) -> None:
    opt = make(approach)
    run(opt, 2)
    view = opt.view()
    n = view["genome"].shape[0]
    assert view["genome"].shape == (n, N_GENES)
    assert view["sigma"].shape == (n, 1)
    assert view["foot_x"].shape == view["foot_y"].shape == (n, N_ANGLES)
    assert view["cell"].dtype == np.int64
    dims = {"EA": 2, "NSGA2": 2, "MAP-WH": 2, "MAP-LIS": 2, "MAP-ST": 4, "RANDOM": 2}[approach]
    assert [k for k in view if k.startswith("desc_")] == [f"desc_{d}" for d in range(dims)]
    has_grid = approach in REPERTOIRE_APPROACHES
    assert (view["cell"] >= 0).all() == has_grid
    assert ("bin_0" in view) == has_grid
    assert ("loss_0" in view) == (approach == "NSGA2")
    if approach == "EA":  # not elitist: the best-ever may have left the population
        assert view["loss"].min() >= opt.best()[1]
    else:
        assert view["loss"].min() == pytest.approx(opt.best()[1])


@pytest.mark.parametrize("approach", BUILT_IN)
def test_best_is_the_best_ever_told_and_survives_a_resume(approach: str) -> None:
    opt = make(approach)
    told = []
    for _ in range(4):
        genomes = opt.ask()
        evaluation = evaluate(genomes, opt.eval_fitness, "paper", n_angles=N_ANGLES)
        opt.tell(genomes, evaluation)
        loss = scalar_loss(
            np.asarray(evaluation.loss), evaluation.error, evaluation.angle_error, opt.fitness
        )
        told.append((loss.min(), genomes[np.argmin(loss)]))
    best_loss, best_genome = min(told, key=lambda t: t[0])
    genome, loss = opt.best()
    assert loss == best_loss == opt.metrics()["best_loss"]
    np.testing.assert_array_equal(genome, best_genome)
    again = make(approach)
    again.load_state_dict(opt.state_dict())
    assert again.best()[1] == loss


def test_random_asks_fresh_uniform_genomes_and_keeps_them_on_the_map_lis_grid() -> None:
    opt = make("RANDOM")
    run(opt, 2)
    first = opt.archive.elites.genome.copy()
    genomes = opt.ask()
    assert not np.isin(genomes, first).any()
    assert opt.archive.space == DESCRIPTOR_SPACES["MAP-LIS"]
    assert opt.settings()["coverage_space"] == "MAP-LIS"


def test_factory_rejects_unknown_names() -> None:
    with pytest.raises(ValueError, match="unknown approach 'GA'; allowed: EA, NSGA2"):
        make_optimizer("GA", fitness="Fp", batch_size=10, mode="paper", seed=0)
    with pytest.raises(ValueError, match="unknown option\\(s\\) 'foo' for EA"):
        make("EA", foo=1)
    with pytest.raises(ValueError, match="unknown fitness 'Fq'"):
        make_optimizer("EA", fitness="Fq", batch_size=10, mode="paper", seed=0)
    with pytest.raises(ValueError, match="batch_size must be a positive integer, got 0"):
        make("EA", batch_size=0)


@pytest.mark.parametrize("fitness", ["Fp", "Fsl"])
def test_scalar_loss_recovers_the_single_objective_fitness(fitness: str) -> None:
    genomes = np.random.default_rng(0).random((300, N_GENES))
    single = evaluate(genomes, fitness)
    double = evaluate(genomes, fitness + "2")
    recovered = scalar_loss(double.loss, double.error, double.angle_error, fitness)
    np.testing.assert_allclose(recovered, single.loss, atol=1e-9)
