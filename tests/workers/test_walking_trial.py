"""Walking trials (fitness F_w) on the real engine: the command a user runs, its claims
against the Table I walk, the same seed giving the same metrics, a resume that equals an
uninterrupted run, NSGA-II's two floors, and what is refused before any work starts."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from linkevo.sim.robot.walk_fitness import BROKEN_LOSS
from linkevo.workers.evaluators import make_evaluator
from linkevo.workers.recorders import NullRecorder
from linkevo.workers.store.artifacts import read_npz
from linkevo.workers.trial import run_trial
from linkevo.workers.trial_spec import TrialSpec, TrialSpecError
from linkevo.workers.walk_evaluator import WalkingEvaluator


def linkevo(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "linkevo.orchestrator", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ},
    )


def test_a_map_lis_walking_trial_walks_what_its_loss_claims(tmp_path):
    out = tmp_path / "cli"
    done = linkevo(
        "trial",
        "--approach",
        "MAP-LIS",
        "--fitness",
        "Fw",
        "--walks",
        "120",
        "--seed",
        "1",
        "--out",
        str(out),
        "--no-progress",
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    assert "walks (" in done.stdout
    metrics = pd.read_csv(out / "metrics.csv")
    assert metrics["walks"].iloc[-1] >= 120 and metrics["walks"].iloc[-2] < 120
    assert {
        "walk_cache_hits",
        "rejected_2d",
        "rejected_build",
        "walkers",
        "best_flat_cm",
        "best_carpet_cm",
    } <= set(metrics.columns)
    assert metrics["rejected_2d"].iloc[-1] > 0  # rejections cost no walk

    again = run_trial(
        TrialSpec.walking("MAP-LIS", 120, seed=1),
        make_evaluator(TrialSpec.walking("MAP-LIS", 120, seed=1)),
        NullRecorder(),
        tmp_path / "again",
    )
    assert (again.out_dir / "metrics.csv").read_text() == (out / "metrics.csv").read_text()

    claimed = -json.loads((out / "result.json").read_text())["best_loss"]
    assert claimed > 30.0  # a sound walker, on the worse floor
    confirmed = json.loads((out / "best_confirmed.json").read_text())
    best = json.loads((out / "best_linkage.json").read_text())
    assert confirmed["repeats"] == 5 and set(confirmed["floors"]) == {"flat", "carpet"}
    assert {"size_cm", "stroke_cm", "lift_cm", "crank_share"} == set(confirmed["shape"])
    assert f"crank share {confirmed['shape']['crank_share']:.2f}" in done.stdout
    assert ("SLIDES" in done.stdout) == confirmed["slides"]
    assert len(confirmed["genome"]) == len(best["genome"])
    log = pd.read_parquet(out / "walks.parquet")
    assert set(log["stage"]) <= {"walked", "cached", "no_lego_build", "no_turn", "failed"}
    assert (log["stage"] == "walked").sum() == metrics["walks"].iloc[-1]
    walked = pd.read_parquet(out / "walkmap.parquet")
    assert {"cell", "floor", "status", "mean_distance_cm", "bin_0", "bin_1"} <= set(walked)
    for floor in ("flat", "carpet"):
        done = linkevo(
            "hexapod",
            "simulate",
            "--linkage",
            str(out / "best_linkage.json"),
            "--floor",
            floor,
            "--json",
            "--no-log",
            cwd=tmp_path,
        )
        assert done.returncode == 0, done.stderr
        table_one = json.loads(done.stdout)
        assert not table_one["breaks"]
        assert table_one["mean_distance_cm"] >= 0.7 * claimed, (floor, table_one, claimed)


class Crashing:
    """A walking evaluator that raises on its `fail_at`-th batch (a crash mid-trial)."""

    def __init__(self, inner: WalkingEvaluator, fail_at: int) -> None:
        self.inner, self.fail_at, self.calls = inner, fail_at, 0

    def submit(self, genomes, bar=None):
        self.calls += 1
        if self.calls == self.fail_at:
            raise RuntimeError("the node went away")
        return self.inner.submit(genomes, bar)

    def __getattr__(self, name):
        return getattr(self.inner, name)


def test_a_resumed_walking_trial_equals_an_uninterrupted_one(tmp_path):
    spec = TrialSpec.walking("MAP-LIS", 40, seed=5, checkpoint_every=2)
    whole = run_trial(spec, make_evaluator(spec), NullRecorder(), tmp_path / "whole")
    folder = tmp_path / "cut"
    with pytest.raises(RuntimeError, match="went away"):
        run_trial(spec, Crashing(make_evaluator(spec), fail_at=6), NullRecorder(), folder)
    state = read_npz(folder / "checkpoint" / "state.npz")
    assert len(state["walks.stage"]) > 0  # the walk log is in the checkpoint
    resumed = run_trial(spec, make_evaluator(spec), NullRecorder(), folder, resume=True)
    assert (folder / "metrics.csv").read_text() == (whole.out_dir / "metrics.csv").read_text()
    assert resumed.metrics["walks"] == whole.metrics["walks"]
    ours, theirs = (pd.read_parquet(d / "walks.parquet") for d in (folder, whole.out_dir))
    same = [c for c in ours.columns if c not in ("compute_s", "genome")]
    pd.testing.assert_frame_equal(ours[same], theirs[same])


def test_the_surrogate_skips_walks_and_a_resumed_trial_refits_the_same_model(tmp_path, monkeypatch):
    from linkevo.workers import walk_surrogate

    monkeypatch.setattr(walk_surrogate, "START", 20)  # a model after 20 walks, then every 20
    monkeypatch.setattr(walk_surrogate, "REFIT_EVERY", 20)
    spec = TrialSpec.walking("MAP-LIS", 60, seed=5, checkpoint_every=2, surrogate=True)
    whole = run_trial(spec, make_evaluator(spec), NullRecorder(), tmp_path / "whole")
    metrics = pd.read_csv(whole.out_dir / "metrics.csv")
    before = metrics[metrics["walks"] < 20]
    assert (before["walks_skipped"] == 0).all()  # no model yet: every candidate is walked
    assert metrics["walks_skipped"].iloc[-1] > 0 and metrics["walks"].iloc[-1] >= 60
    log = pd.read_parquet(whole.out_dir / "walks.parquet")
    assert (log["stage"] == "walked").sum() == metrics["walks"].iloc[-1]  # skipped: not built
    assert np.isfinite(pd.read_parquet(whole.out_dir / "repertoire.parquet")["loss"]).all()

    folder = tmp_path / "cut"
    crash_at = int(metrics.loc[metrics["walks"] >= 30, "iteration"].iloc[0]) + 1
    with pytest.raises(RuntimeError, match="went away"):
        run_trial(spec, Crashing(make_evaluator(spec), fail_at=crash_at), NullRecorder(), folder)
    assert int(read_npz(folder / "checkpoint" / "state.npz")["surrogate.fits"]) >= 1
    run_trial(spec, make_evaluator(spec), NullRecorder(), folder, resume=True)
    assert (folder / "metrics.csv").read_text() == (whole.out_dir / "metrics.csv").read_text()


def test_a_sail_trial_walks_what_the_model_proposes_and_resumes_to_the_same_maps(
    tmp_path, monkeypatch
):
    from linkevo.workers import walk_sail

    monkeypatch.setattr(walk_sail, "START", 12)  # a model after 12 walks
    monkeypatch.setattr(walk_sail, "GENERATIONS", 4)  # a small illumination per round
    monkeypatch.setattr(walk_sail, "CHILDREN", 32)
    spec = TrialSpec.walking("MAP-LIS", 36, seed=3, checkpoint_every=1, surrogate="sail")
    whole = run_trial(spec, make_evaluator(spec), NullRecorder(), tmp_path / "whole")
    metrics = pd.read_csv(whole.out_dir / "metrics.csv")
    assert metrics["walks"].iloc[-1] == 36  # never past its budget
    rounds = int(metrics.loc[metrics["walks"] >= 12, "iteration"].iloc[0])
    sail = metrics[metrics["iteration"] > rounds]  # the model's rounds
    assert len(sail) and (sail["rejected_2d"] == metrics["rejected_2d"].iloc[rounds - 1]).all()
    assert (sail["evaluations"].diff().dropna() <= walk_sail.PROPOSALS).all()
    prediction = pd.read_parquet(whole.out_dir / "prediction_map.parquet")
    assert len(prediction) > 36 and prediction["cell"].is_unique
    assert {"flat_predicted_cm", "carpet_spread_cm", "carpet_p_break", "walked"} <= set(prediction)
    repertoire = pd.read_parquet(whole.out_dir / "repertoire.parquet")
    walked = prediction["cell"].isin(repertoire["cell"])
    assert (prediction["walked"] == walked).all() and (~walked).any()

    folder = tmp_path / "cut"
    with pytest.raises(RuntimeError, match="went away"):
        run_trial(spec, Crashing(make_evaluator(spec), fail_at=rounds + 1), NullRecorder(), folder)
    run_trial(spec, make_evaluator(spec), NullRecorder(), folder, resume=True)
    assert (folder / "metrics.csv").read_text() == (whole.out_dir / "metrics.csv").read_text()
    again = pd.read_parquet(folder / "prediction_map.parquet")
    pd.testing.assert_frame_equal(again, prediction)


def test_nsga2_walks_the_two_floors_as_its_two_objectives(tmp_path):
    spec = TrialSpec.walking("NSGA2", 30, seed=2)
    result = run_trial(spec, make_evaluator(spec), NullRecorder(), tmp_path)
    population = pd.read_parquet(tmp_path / "population.parquet")
    assert {"loss_0", "loss_1", "front"} <= set(population.columns)
    np.testing.assert_array_equal(
        population["loss"], np.maximum(population["loss_0"], population["loss_1"])
    )
    assert "hypervolume" in result.metrics and result.metrics["walks"] >= 30
    assert not (tmp_path / "walkmap.parquet").exists()  # a population has no cells
    log = pd.read_parquet(tmp_path / "walks.parquet")
    sound = log[(log["stage"] == "walked") & ~log["carpet_breaks"]]
    assert (sound["flat_status"] == "walked").all()  # no bar: both floors count for NSGA-II


def test_broken_walks_lose_to_every_sound_one(tmp_path):
    spec = TrialSpec.walking("RANDOM", 20, seed=4)
    run_trial(spec, make_evaluator(spec), NullRecorder(), tmp_path)
    log = pd.read_parquet(tmp_path / "walks.parquet")
    assert log["carpet_breaks"].any() and (~log["carpet_breaks"]).any()
    repertoire = pd.read_parquet(tmp_path / "repertoire.parquet")
    walked = pd.read_parquet(tmp_path / "walkmap.parquet")
    broken_cells = set(walked.loc[walked["breaks"], "cell"])
    losses = repertoire.set_index("cell")["loss"]
    sound = losses.drop(index=list(broken_cells), errors="ignore")
    assert losses.loc[list(broken_cells)].min() >= BROKEN_LOSS - 400
    assert sound[sound < BROKEN_LOSS / 2].max() < losses.loc[list(broken_cells)].min()


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (
            lambda: TrialSpec("MAP-LIS", "Fw", 1000, 32),
            r"walks must be an integer in \[1, 10,000,000\]",
        ),
        (lambda: TrialSpec("MAP-LIS", "Fp", 1000, 32, walks=5), "for fitness Fw only"),
        (lambda: TrialSpec.walking("MAP-LIS", 0), r"walks must be an integer in \[1, 10,000,000\]"),
        (lambda: TrialSpec.walking("EA", 10, walk_rerank=3), "walk_rerank is for the path"),
        (lambda: TrialSpec.walking("NSGA2", 10, surrogate=True), "surrogate = 'screen' is for"),
        (
            lambda: TrialSpec("MAP-LIS", "Fp", 1000, 32, surrogate=True),
            "surrogate = 'screen' is for",
        ),
        (lambda: TrialSpec.walking("MAP-LIS", 300, surrogate="model"), "surrogate must be one of"),
        (lambda: TrialSpec.walking("MAP-AU", 300, surrogate="sail"), "descriptors are learned"),
        (lambda: TrialSpec.walking("MAP-LIS", 50, surrogate="sail"), "allowed: walks > 64"),
        (lambda: TrialSpec.walking("MAP-LIS", 300, walk_model="abc"), "set surrogate = 'sail'"),
    ],
)
def test_a_walking_trial_is_refused_as_specified(make, message):
    with pytest.raises(TrialSpecError, match=message):
        make()


def test_the_command_refuses_a_walking_trial_without_its_budget(tmp_path):
    done = linkevo(
        "trial", "--approach", "EA", "--fitness", "Fw", "--out", str(tmp_path / "t"), cwd=tmp_path
    )
    assert done.returncode == 2 and "--fitness Fw needs --walks N" in done.stderr
    done = linkevo(
        "trial",
        "--approach",
        "EA",
        "--fitness",
        "Fp",
        "--walks",
        "5",
        "--out",
        str(tmp_path / "t"),
        cwd=tmp_path,
    )
    assert done.returncode == 2 and "--walks is for --fitness Fw only" in done.stderr
    assert not (tmp_path / "t" / "metrics.csv").exists()
