"""The one trial loop: artefacts, reproducibility, checkpoint and exact resume, spec checks."""

from __future__ import annotations

import csv
import itertools
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from linkevo.sim.linkage.linkage_doc import from_document
from linkevo.sim.linkage.path_diversity import path_diversity
from linkevo.workers.checkpoint import CheckpointError
from linkevo.workers.evaluators import LocalEvaluator, Stateless
from linkevo.workers.recorders import NullRecorder
from linkevo.workers.store.artifacts import read_npz
from linkevo.workers.trial import run_trial
from linkevo.workers.trial_spec import TrialSpec, TrialSpecError, build_optimizer

BATCH = 100


class ListRecorder:
    """Keeps what the loop reports, to assert on it."""

    def __init__(self) -> None:
        self.iterations: list[tuple[int, dict[str, float]]] = []
        self.finals: list[tuple[int, dict[str, float]]] = []
        self.artifacts: list[Path] = []

    def log_iteration(self, iteration: int, metrics: dict[str, float]) -> None:
        """Keeps an iteration's row, or apart the end-of-trial measures (no evaluations)."""
        kept = self.iterations if "evaluations" in metrics else self.finals
        kept.append((iteration, dict(metrics)))

    def log_artifacts(self, out_dir: Path) -> None:
        self.artifacts.append(out_dir)


def spec_for(approach: str, **changes) -> TrialSpec:
    values = {
        "approach": approach,
        "fitness": "Fp",
        "evaluations": 6 * BATCH,
        "batch_size": BATCH,
        "seed": 7,
        "n_angles": 12,
        "checkpoint_every": 2,
    }
    return TrialSpec(**(values | changes))


def evaluator_for(spec: TrialSpec) -> LocalEvaluator:
    return LocalEvaluator(spec.eval_fitness, spec.mode, spec.target, spec.n_angles)


class WatchingEvaluator(Stateless):
    """Notes how many iterations the recorder holds at each submit and each collect."""

    def __init__(self, inner: LocalEvaluator, recorder: ListRecorder) -> None:
        self.inner = inner
        self.recorder = recorder
        self.at_submit: list[int] = []
        self.at_collect: list[int] = []

    def submit(self, genomes: np.ndarray, bar=None):
        self.at_submit.append(len(self.recorder.iterations))
        pending = self.inner.submit(genomes, bar)

        def collect():
            self.at_collect.append(len(self.recorder.iterations))
            return pending()

        return collect

    def __call__(self, genomes: np.ndarray):
        return self.submit(genomes)()


def read_rows(path: Path) -> list[list[str]]:
    with open(path, newline="") as f:
        return list(csv.reader(f))


@pytest.mark.parametrize("approach", ["MAP-LIS", "NSGA2"])
def test_trial_writes_every_artefact(approach: str, tmp_path: Path) -> None:
    spec = spec_for(approach)
    recorder = ListRecorder()
    result = run_trial(spec, evaluator_for(spec), recorder, tmp_path)
    assert result.iterations == 6 and result.evaluations == 6 * BATCH
    rows = read_rows(tmp_path / "metrics.csv")
    header = rows[0]
    assert header[:6] == [
        "iteration",
        "evaluations",
        "best_loss",
        "mean_loss",
        "coverage",
        "qd_score",
    ]
    assert ("hypervolume" in header) == (approach == "NSGA2")
    assert [float(r[1]) for r in rows[1:]] == [BATCH * i for i in range(1, 7)]
    best = [float(r[2]) for r in rows[1:]]
    if approach == "MAP-LIS":  # an archive never loses its best
        assert all(b <= a for a, b in itertools.pairwise(best))
    assert [i for i, _ in recorder.iterations] == list(range(1, 7))
    assert recorder.artifacts == [tmp_path]
    ((step, final),) = recorder.finals  # the path diversity of what the trial kept
    kept = pd.read_parquet(next(tmp_path.glob("*.parquet")))
    expected = path_diversity(np.stack(kept.foot_x), np.stack(kept.foot_y), kept.loss.to_numpy())
    assert step == 6 and final == {"path_diversity": pytest.approx(expected, rel=1e-6)}
    assert 0.0 < final["path_diversity"] < 2.0

    name = "repertoire.parquet" if approach == "MAP-LIS" else "population.parquet"
    table = pq.read_table(tmp_path / name)
    genome_type = table.schema.field("genome").type
    assert pa.types.is_list(genome_type) and pa.types.is_float64(genome_type.value_type)
    frame = table.to_pandas()
    expected_rows = round(float(rows[-1][4]) * 10_000) if approach == "MAP-LIS" else BATCH
    assert len(frame) == expected_rows
    assert np.stack(frame["genome"]).shape == (len(frame), 56)
    assert np.stack(frame["foot_x"]).shape == (len(frame), 12)
    if approach == "MAP-LIS":
        assert (frame["cell"] >= 0).all() and frame["cell"].is_unique
        assert {"bin_0", "bin_1"} <= set(frame.columns)
    else:
        assert (frame["cell"] == -1).all()
        assert {"loss_0", "loss_1", "front"} <= set(frame.columns)
    assert frame["loss"].min() == pytest.approx(result.best_loss)

    doc = json.loads((tmp_path / "best_linkage.json").read_text())
    genome, mode = from_document(doc)
    assert mode == "paper"
    best_row = frame.loc[frame["loss"].idxmin()]
    np.testing.assert_allclose(genome, np.asarray(best_row["genome"]), atol=1e-12)
    assert (tmp_path / "best_linkage.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    settings = json.loads((tmp_path / "settings.json").read_text())
    assert settings["spec"]["approach"] == approach
    assert settings["optimizer"]["eval_fitness"] == spec.eval_fitness
    assert "numpy" in settings["versions"]
    state = read_npz(tmp_path / "checkpoint" / "state.npz")  # loads without pickle
    assert int(state["checkpoint.rows"]) == 6


@pytest.mark.parametrize("approach", ["EA", "MAP-LIS"])
def test_an_iterations_bookkeeping_overlaps_the_next_evaluation(approach: str, tmp_path: Path):
    spec = spec_for(approach)
    recorder = ListRecorder()
    watching = WatchingEvaluator(evaluator_for(spec), recorder)
    run_trial(spec, watching, recorder, tmp_path)
    # Iteration k is recorded after batch k + 1 was submitted and before it is collected.
    assert watching.at_submit == [0, 0, 1, 2, 3, 4]
    assert watching.at_collect == [0, 1, 2, 3, 4, 5]
    # ... with the metrics it had right after its tell().
    optimizer, evaluator, expected = build_optimizer(spec), evaluator_for(spec), []
    for _ in range(spec.iterations):
        genomes = optimizer.ask()
        optimizer.tell(genomes, evaluator(genomes))
        expected.append((optimizer.iteration, optimizer.metrics()))
    np.testing.assert_equal(recorder.iterations, expected)


def test_same_seed_same_metrics_other_seed_differs(tmp_path: Path) -> None:
    spec = spec_for("EA", evaluations=4 * BATCH)
    run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path / "a")
    run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path / "b")
    other = spec_for("EA", evaluations=4 * BATCH, seed=8)
    run_trial(other, evaluator_for(other), NullRecorder(), tmp_path / "c")
    a, b, c = (read_rows(tmp_path / d / "metrics.csv") for d in "abc")
    assert a == b
    assert a[0] == c[0] and a[1:] != c[1:]


@pytest.mark.parametrize("approach", ["EA", "NSGA2", "MAP-ST"])
def test_resume_continues_exactly_as_an_uninterrupted_run(
    approach: str, tmp_path: Path, crashing_evaluator
) -> None:
    spec = spec_for(approach, evaluations=7 * BATCH)
    run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path / "whole")

    crashing = crashing_evaluator(evaluator_for(spec), fail_at=6)
    with pytest.raises(RuntimeError, match="evaluator crashed"):
        run_trial(spec, crashing, NullRecorder(), tmp_path / "cut")
    assert len(read_rows(tmp_path / "cut" / "metrics.csv")) == 1 + 5  # rows beyond the checkpoint

    recorder = ListRecorder()
    result = run_trial(spec, evaluator_for(spec), recorder, tmp_path / "cut", resume=True)
    whole = read_rows(tmp_path / "whole" / "metrics.csv")
    assert read_rows(tmp_path / "cut" / "metrics.csv") == whole
    assert [i for i, _ in recorder.iterations] == list(range(1, 8))  # 1..4 replayed
    assert [m["best_loss"] for _, m in recorder.iterations] == [float(r[2]) for r in whole[1:]]
    assert result.iterations == 7
    one = pd.read_parquet(next((tmp_path / "whole").glob("*.parquet")))
    two = pd.read_parquet(next((tmp_path / "cut").glob("*.parquet")))
    np.testing.assert_array_equal(np.stack(one["genome"]), np.stack(two["genome"]))


def test_a_partial_row_after_the_checkpoint_is_dropped_on_resume(
    tmp_path: Path, crashing_evaluator
) -> None:
    """A writer killed mid-row leaves half a row after the checkpointed ones."""
    spec = spec_for("EA", evaluations=7 * BATCH)
    run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path / "whole")
    with pytest.raises(RuntimeError, match="evaluator crashed"):
        run_trial(
            spec,
            crashing_evaluator(evaluator_for(spec), fail_at=6),
            NullRecorder(),
            tmp_path / "cut",
        )
    metrics = tmp_path / "cut" / "metrics.csv"
    metrics.write_text(metrics.read_text() + "6.0,600.0,12.3")
    run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path / "cut", resume=True)
    assert read_rows(metrics) == read_rows(tmp_path / "whole" / "metrics.csv")


def test_resume_refuses_a_checkpoint_of_another_trial(tmp_path: Path) -> None:
    spec = spec_for("EA", evaluations=2 * BATCH)
    run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path)
    other = spec_for("EA", evaluations=2 * BATCH, seed=99)
    with pytest.raises(
        CheckpointError, match=r"another trial; differing: seed \(saved 7, now 99\)"
    ):
        run_trial(other, evaluator_for(other), NullRecorder(), tmp_path, resume=True)


def test_resume_with_a_larger_budget_extends_the_trial(tmp_path: Path) -> None:
    short = spec_for("MAP-WH", evaluations=3 * BATCH)
    run_trial(short, evaluator_for(short), NullRecorder(), tmp_path / "ext")
    longer = spec_for("MAP-WH", evaluations=5 * BATCH)
    result = run_trial(longer, evaluator_for(longer), NullRecorder(), tmp_path / "ext", resume=True)
    run_trial(longer, evaluator_for(longer), NullRecorder(), tmp_path / "whole")
    assert result.iterations == 5
    assert read_rows(tmp_path / "ext" / "metrics.csv") == read_rows(
        tmp_path / "whole" / "metrics.csv"
    )


def test_wall_clock_limit_stops_after_an_iteration(tmp_path: Path) -> None:
    spec = spec_for("EA", max_seconds=1e-9)
    result = run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path)
    assert result.stopped_by == "max_seconds" and result.iterations == 1
    assert json.loads((tmp_path / "result.json").read_text())["stopped_by"] == "max_seconds"


def test_budget_counts_whole_batches(tmp_path: Path) -> None:
    spec = spec_for("MAP-LIS", evaluations=3 * BATCH + BATCH // 2)
    result = run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path)
    assert result.evaluations == 3 * BATCH and spec.iterations == 3


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"approach": "GA"}, "unknown approach 'GA'; allowed: EA, NSGA2, MAP-WH"),
        ({"fitness": "Fp2"}, "unknown fitness 'Fp2'; allowed: Fp, Fsl"),
        ({"evaluations": -5}, r"evaluations must be an integer >= the batch size \(100\), got -5"),
        ({"evaluations": 50}, r"evaluations must be an integer >= the batch size \(100\), got 50"),
        ({"batch_size": 0}, "batch size must be a positive integer, got 0"),
        ({"mode": "fast"}, "unknown mode 'fast'; allowed: paper, legacy"),
        ({"seed": -1}, "seed must be a non-negative integer, got -1"),
        ({"target": "nowhere.json"}, "target 'nowhere.json' is neither a published target"),
        ({"checkpoint_every": 0}, "checkpoint_every must be a positive integer, got 0"),
        ({"max_seconds": -1.0}, "max_seconds must be a positive number or None, got -1.0"),
    ],
)
def test_bad_spec_is_refused_with_a_clear_message(changes: dict, message: str) -> None:
    with pytest.raises(TrialSpecError, match=message):
        spec_for(**({"approach": "EA"} | changes))


def test_spec_knows_the_evaluator_fitness() -> None:
    assert spec_for("NSGA2").eval_fitness == "Fp2"
    assert spec_for("NSGA2", fitness="Fsl").eval_fitness == "Fsl2"
    assert spec_for("MAP-LIS").eval_fitness == "Fp"


def test_user_target_file(tmp_path: Path) -> None:
    target = tmp_path / "flat.json"
    target.write_text(json.dumps({"step": [[-4, -1], [0, -1], [4, -1]], "lift": [[0, 2]]}))
    spec = spec_for("EA", target=str(target), evaluations=BATCH)
    run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path / "out")
    settings = json.loads((tmp_path / "out" / "settings.json").read_text())
    assert settings["target"]["step"] == [[-4.0, -1.0], [0.0, -1.0], [4.0, -1.0]]


def _damage(state: dict[str, np.ndarray], how: str) -> None:
    """Damages a MAP-LIS checkpoint's arrays in place, as a bad disk or a bad edit would."""
    if how == "wrong shape":
        state["archive.genome"] = state["archive.genome"][:, :55]
    elif how == "shifted cells":
        state["archive.cells"] = state["archive.cells"] + 1
    elif how == "NaN losses":
        state["archive.loss"] = np.full_like(state["archive.loss"], np.nan)
    elif how == "bad RNG state":
        state["optimizer.rng"] = np.array('{"bit_generator": "PCG64", "state": 3}')
    elif how == "missing key":
        del state["archive.loss"]
    elif how == "genomes as strings":
        state["archive.genome"] = state["archive.genome"].astype(str).astype("<U3")
    elif how == "negative row count":
        state["checkpoint.rows"] = np.array(-4, dtype=np.int64)
    elif how == "negative iteration":
        state["optimizer.iteration"] = np.array(-5, dtype=np.int64)
    elif how == "negative sigma":
        state["archive.sigma"] = -state["archive.sigma"] - 0.1
    elif how == "infinite foot":
        state["archive.foot_x"] = state["archive.foot_x"].copy()
        state["archive.foot_x"][0, 0] = np.inf


@pytest.mark.parametrize(
    ("how", "names"),
    [
        ("wrong shape", "archive.genome (float64, shape"),
        ("shifted cells", "do not bin to their saved cells"),
        ("NaN losses", "archive.loss"),
        ("bad RNG state", "does not load"),
        ("missing key", "missing entry 'archive.loss'"),
        ("genomes as strings", "archive.genome (<U3"),
        ("negative row count", "impossible (rows -4"),
        ("negative iteration", "optimizer.iteration -5"),
        ("negative sigma", "archive.sigma (float64"),
        ("infinite foot", "archive.foot_x (float64"),
    ],
)
def test_a_damaged_checkpoint_is_refused_naming_the_file_and_the_remedy(
    tmp_path: Path, how: str, names: str
) -> None:
    from linkevo.workers.store.artifacts import write_npz_atomic

    spec = spec_for("MAP-LIS", evaluations=3 * BATCH)
    run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path)
    path = tmp_path / "checkpoint" / "state.npz"
    state = read_npz(path)
    _damage(state, how)
    write_npz_atomic(path, state)
    damaged = path.read_bytes()
    with pytest.raises(CheckpointError) as caught:
        run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path, resume=True)
    message = str(caught.value)
    assert f"cannot resume from {path}" in message and names in message, message
    assert "--restart-trial KEY" in message
    assert path.read_bytes() == damaged  # left for the user to look at


def test_resume_without_a_checkpoint_deletes_nothing_it_did_not_write(tmp_path: Path) -> None:
    spec = spec_for("EA", evaluations=2 * BATCH)
    (tmp_path / "checkpoint").mkdir()
    own = tmp_path / "checkpoint" / "state.npz.before-upgrade"
    own.write_bytes(b"the user's copy")
    (tmp_path / "notes.txt").write_text("kept")
    run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path, resume=True)
    assert own.read_bytes() == b"the user's copy" and (tmp_path / "notes.txt").is_file()
    assert (tmp_path / "checkpoint" / "state.npz").is_file()


def test_walk_rerank_walks_the_best_linkages_and_keeps_the_furthest(tmp_path: Path) -> None:
    """`walk_rerank`: the K lowest-loss linkages that pass the physical checks are walked
    on the simulated robot; the furthest one that does not break is the best walker."""
    spec = TrialSpec("MAP-LIS", "Fp", evaluations=6000, batch_size=1000, seed=1, walk_rerank=3)
    evaluator = LocalEvaluator(spec.eval_fitness, spec.mode, spec.target, spec.n_angles)
    logged: list[dict] = []

    class Recorder(NullRecorder):
        def log_iteration(self, iteration: int, metrics: dict[str, float]) -> None:
            logged.append(metrics)

    result = run_trial(spec, evaluator, Recorder(), tmp_path)
    walks = pd.read_parquet(tmp_path / "walk_rerank.parquet")
    assert len(walks) == 3 and (walks["floor"] == "flat").all()
    assert list(walks["loss"]) == sorted(walks["loss"])
    sound = walks[(walks["status"] == "walked") & ~walks["breaks"]]
    assert len(sound) >= 1
    best = sound.loc[sound["mean_distance_cm"].idxmax()]
    assert result.metrics["best_walk_cm"] == pytest.approx(best["mean_distance_cm"])
    assert logged[-1] == {"best_walk_cm": result.metrics["best_walk_cm"]}
    document = json.loads((tmp_path / "best_walker.json").read_text())
    assert document["meta"]["cell"] == best["cell"]
    genome, _ = from_document(document)
    assert np.array_equal(genome, best["genome"])


def test_a_checkpoint_whose_header_claims_more_than_it_holds_is_refused(tmp_path: Path) -> None:
    """A forged array header (a shape of 10**12 rows) is refused by name before any
    memory is taken for it."""
    import io
    import zipfile

    spec = spec_for("MAP-LIS", evaluations=2 * BATCH)
    run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path)
    path = tmp_path / "checkpoint" / "state.npz"
    state = read_npz(path)
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": (10**12, 56)}
    )
    with zipfile.ZipFile(path, "w") as archive:
        for name, array in state.items():
            member = io.BytesIO()
            np.lib.format.write_array(member, array, allow_pickle=False)
            forged = header.getvalue() + b"\0" * 64
            archive.writestr(
                f"{name}.npy", forged if name == "archive.genome" else member.getvalue()
            )
    with pytest.raises(CheckpointError) as caught:
        run_trial(spec, evaluator_for(spec), NullRecorder(), tmp_path, resume=True)
    assert "array 'archive.genome' claims shape (1000000000000, 56)" in str(caught.value)
