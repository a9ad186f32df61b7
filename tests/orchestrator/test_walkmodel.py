"""`linkevo walkmodel` end to end, as a user repeats it: quick MAP-LIS and MAP-WH trials in
a real store, their walk maps made by `linkevo walkmap` on a real local Ray instance, the
model fitted with a repertoire held out, another trial predicted, and its predicted layer
in the explorer (a real headless Chromium) and on a pulled build sheet."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pandas as pd
import pytest
import torch
from mlflow.tracking import MlflowClient

from linkevo.algorithms.walk_model import WalkModel
from linkevo.orchestrator.cli import main
from linkevo.workers.store.runs import RunStore
from linkevo.workers.trial_spec import TrialSpec
from tests.helpers.browser import chromium, open_explorer, point_at
from tests.helpers.trials import record_trials

GRID = "0a0b0c0d0e1f"


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    specs = [
        TrialSpec("MAP-LIS", "Fp", evaluations=4000, batch_size=1000, seed=3),
        TrialSpec("MAP-WH", "Fp", evaluations=4000, batch_size=1000, seed=3),
        TrialSpec("MAP-ST", "Fp", evaluations=4000, batch_size=1000, seed=4),
    ]
    return record_trials(tmp_path_factory.mktemp("walkmodel"), GRID, specs)


def run(*words: str) -> tuple[int, str]:
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(list(words))
    return code, printed.getvalue()


@pytest.fixture(scope="module")
def fitted(store, ray_local) -> dict:
    """The walk maps (150 cells of MAP-LIS, 40 of MAP-WH, 2-s walks) and the model fitted
    on MAP-LIS's with MAP-WH's held out: what `walkmodel fit --json` printed."""
    uri, runs = store
    for approach, cells in (("MAP-LIS", "best:150"), ("MAP-WH", "best:40")):
        code, _ = run(
            "walkmap", runs[approach], "--cells", cells, "--seconds", "2", "--tracking-uri", uri
        )
        assert code == 0
    code, printed = run(
        "walkmodel",
        "fit",
        runs["MAP-LIS"],
        runs["MAP-WH"],
        "--holdout",
        "0.5",
        "--seed",
        "1",
        "--json",
        "--tracking-uri",
        uri,
    )
    assert code == 0
    return json.loads(printed)


def test_fit_holds_out_a_whole_repertoire_and_logs_a_model_of_its_own_kind(store, fitted, tmp_path):
    uri, runs = store
    assert len(fitted["held_out"]) == 1 and len(fitted["trained_on"]) == 1
    assert set(fitted["held_out"] + fitted["trained_on"]) == {"MAP-LIS/Fp/00", "MAP-WH/Fp/00"}
    for name in ("spearman_flat", "spearman_carpet", "break_auc"):
        assert fitted[name] is None or -1.0 <= fitted[name] <= 1.0
    assert fitted["walks"] > 0
    client = MlflowClient(uri)
    model_run = client.get_run(fitted["run_id"])
    assert model_run.data.tags["linkevo.kind"] == "walk_model"
    assert model_run.info.status == "FINISHED"
    names = {a.path for a in client.list_artifacts(fitted["run_id"])}
    assert {"walk_model.pt", "walk_model.json", "walk_model.png"} <= names
    weights = client.download_artifacts(fitted["run_id"], "walk_model.pt", str(tmp_path))
    WalkModel.from_state_dict(torch.load(weights, weights_only=True))
    path = client.download_artifacts(fitted["run_id"], "walk_model.json", str(tmp_path))
    description = json.loads(Path(path).read_text())
    assert description["held_out"] == [runs[fitted["held_out"][0].split("/")[0]]]
    assert "foot_x_0" in description["features"]["names"]


def test_predict_gives_every_filled_cell_a_row_per_floor(store, fitted, tmp_path):
    uri, runs = store
    code, printed = run("walkmodel", "predict", runs["MAP-ST"], "--tracking-uri", uri)
    assert code == 0 and f"predicted by walk model {fitted['run_id']}" in printed
    store_ = RunStore.open(uri)
    table = store_.repertoire(runs["MAP-ST"], tmp_path / "rep")
    predicted = store_.walk_prediction(runs["MAP-ST"], tmp_path / "pred")
    assert len(predicted) == 2 * len(table)
    for floor in ("flat", "carpet"):
        part = predicted[predicted["floor"] == floor]
        assert sorted(part["cell"]) == sorted(table["cell"])
        assert part["predicted_cm"].notna().all() and part["p_break"].between(0, 1).all()


def test_the_explorer_and_pull_mark_predicted_walks_as_predicted(store, fitted, tmp_path, capsys):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    uri, runs = store
    run_id = runs["MAP-ST"]
    assert run("walkmodel", "predict", run_id, "--tracking-uri", uri)[0] == 0
    predicted = RunStore.open(uri).walk_prediction(run_id, tmp_path / "pred")
    flat = predicted[predicted["floor"] == "flat"].sort_values("predicted_cm")
    cell = int(flat.iloc[len(flat) // 2]["cell"])
    guess = flat.set_index("cell").loc[cell]
    out = tmp_path / "page.html"
    assert main(["explore", run_id, "--tracking-uri", uri, "--out", str(out), "--no-log"]) == 0
    with chromium() as browser:
        open_explorer(browser, out)
        colour = Select(browser.find_element(By.ID, "colour-by"))
        assert [o.text for o in colour.options] == ["loss", "distance, flat", "distance, carpet"]
        colour.select_by_visible_text("distance, flat")
        legend = browser.find_element(By.ID, "legend").text
        assert f"predicted by the walk model {fitted['run_id']}, not walked" in legend
        assert browser.execute_script("return window.explorer.predictedOnMap(arguments[0])", cell)
        point_at(browser, cell)
        hovered = browser.find_element(By.ID, "hover-info").text
        assert f"cell {cell}:" in hovered
        shown = f"flat: {guess['predicted_cm']:.1f} ± {guess['spread_cm']:.1f} cm (predicted)"
        assert shown in hovered
    capsys.readouterr()
    pulled = tmp_path / "pulled"
    assert main(["pull", f"{run_id}:{cell}", "--out", str(pulled), "--tracking-uri", uri]) == 0
    assert f"predicted walk: flat {guess['predicted_cm']:.1f}" in capsys.readouterr().err
    document = json.loads((pulled / "linkage.json").read_text())
    assert document["predicted_walk"]["flat"]["walk_model"] == fitted["run_id"]
    assert "simulated_walk" not in document


def test_a_model_is_found_by_its_run_and_bad_references_are_refused(store, fitted, capsys):
    uri, runs = store
    assert (
        main(
            [
                "walkmodel",
                "predict",
                runs["MAP-ST"],
                "--model",
                runs["MAP-LIS"],
                "--tracking-uri",
                uri,
            ]
        )
        == 2
    )
    assert "is not a walk model" in capsys.readouterr().err
    assert main(["walkmodel", "fit", runs["MAP-ST"], "--tracking-uri", uri]) == 2
    assert "has no walk map to learn from" in capsys.readouterr().err
    assert main(["walkmodel", "fit", runs["MAP-LIS"], "--holdout", "1", "--tracking-uri", uri]) == 2
    assert "--holdout: '1' is not allowed: a share in [0, 1)" in capsys.readouterr().err
    code = main(["walkmodel", "fit", runs["MAP-LIS"], "--holdout", "0.5", "--tracking-uri", uri])
    assert code == 2 and "leaves none to train on" in capsys.readouterr().err
    kinds = [r.data.tags.get("linkevo.kind") for r in MlflowClient(uri).search_runs(["0", "1"])]
    assert kinds.count("walk_model") == 1  # refused fits logged nothing


def test_a_walk_prediction_frame_is_as_the_reader_checks_it(store, fitted, tmp_path):
    uri, runs = store
    frame = pd.read_parquet(
        MlflowClient(uri).download_artifacts(runs["MAP-ST"], "walkpred.parquet", str(tmp_path))
    )
    assert list(frame.columns[:5]) == ["cell", "floor", "predicted_cm", "spread_cm", "p_break"]


def test_a_sail_trial_starts_from_the_model_and_its_predicted_cells_are_pulled_and_shown(
    store, fitted, tmp_path, capsys, monkeypatch
):
    """`linkevo trial --surrogate sail --walk-model RUN_ID`: the model proposes from the
    second batch; a never-walked cell of the prediction map is pulled with its prediction
    apart from any walk, walks with `hexapod simulate`, and is marked predicted on the
    explorer's map."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    from linkevo.workers import walk_sail

    monkeypatch.setattr(walk_sail, "GENERATIONS", 4)
    monkeypatch.setattr(walk_sail, "CHILDREN", 32)
    uri, runs = store
    out = tmp_path / "sail"
    words = ["--approach", "MAP-LIS", "--fitness", "Fw", "--walks", "20", "--seed", "2"]
    words += ["--surrogate", "sail", "--walk-model", fitted["run_id"], "--tracking-uri", uri]
    assert main(["trial", *words, "--out", str(out), "--no-progress"]) == 0
    metrics = pd.read_csv(out / "metrics.csv")
    assert metrics["walks"].iloc[-1] == 20
    assert (metrics["rejected_2d"].iloc[1:] == metrics["rejected_2d"].iloc[0]).all()  # proposed
    refused = ["trial", *words[:-4], "--walk-model", runs["MAP-ST"], "--tracking-uri", uri]
    assert main([*refused, "--out", str(tmp_path / "no")]) == 2
    assert "is not a walk model" in capsys.readouterr().err and not (tmp_path / "no").exists()
    client = MlflowClient(uri)
    tags = {"grid_id": GRID, "linkevo.kind": "trial", "approach": "MAP-LIS", "fitness": "Fw"}
    run_id = client.create_run("0", run_name="MAP-LIS/Fw/00", tags=tags).info.run_id
    client.log_param(run_id, "mode", "paper")
    client.log_artifacts(run_id, str(out))
    client.set_terminated(run_id)

    prediction = pd.read_parquet(out / "prediction_map.parquet")
    never = prediction[~prediction["walked"]].sort_values("loss")
    cell = int(never["cell"].iloc[0])
    capsys.readouterr()
    pulled = tmp_path / "pulled"
    assert main(["pull", f"{run_id}:{cell}", "--out", str(pulled), "--tracking-uri", uri]) == 0
    printed = capsys.readouterr().err
    assert f"cell {cell} of its prediction map (SAIL: predicted, never walked)" in printed
    flat = never.iloc[0]["flat_predicted_cm"]
    assert f"predicted walk: flat {flat:.1f}" in printed and "simulated walk" not in printed
    document = json.loads((pulled / "linkage.json").read_text())
    assert document["predicted_walk"]["flat"]["walk_model"] == "fitted on this SAIL trial's walks"
    assert "simulated_walk" not in document
    words = ["hexapod", "simulate", "--linkage", str(pulled / "linkage.json"), "--floor", "flat"]
    code, printed = run(*words, "--seconds", "3", "--json", "--no-log")
    walked = json.loads(printed)  # a real walk to set beside the prediction
    assert code == 0 and (walked["breaks"] or walked["mean_distance_cm"] is not None)

    page = tmp_path / "page.html"
    assert main(["explore", run_id, "--tracking-uri", uri, "--out", str(page), "--no-log"]) == 0
    with chromium() as browser:
        open_explorer(browser, page)
        Select(browser.find_element(By.ID, "colour-by")).select_by_visible_text("distance, flat")
        legend = browser.find_element(By.ID, "legend").text
        assert "predicted by the walk model fitted on this SAIL trial's walks, not walked" in legend
        assert browser.execute_script("return window.explorer.predictedOnMap(arguments[0])", cell)
