"""Tests for `linkevo explore`: the page's data, the CLI, and the page in a real headless
Chromium (Debian's `chromium` driven by selenium through `chromium-driver`)."""

from __future__ import annotations

import base64
import gzip
import json
import re
import time
from pathlib import Path

import numpy as np
import pytest
from mlflow.entities import Param
from mlflow.tracking import MlflowClient

from linkevo.orchestrator.cli import main
from linkevo.orchestrator.explore import repertoire_view
from linkevo.sim import decode, simulate
from linkevo.sim.linkage.physical import physical_checks
from linkevo.workers.store.runs import RunStore, TrialRun
from linkevo.workers.store.tracking import ensure_experiment
from linkevo.workers.trial_spec import TrialSpec
from tests.helpers.browser import chromium, open_explorer, point_at
from tests.helpers.trials import record_trials

GRID = "e0e0e0e0e0e0"


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A real sqlite store with a grid of three real trials (MAP-ST, MAP-LIS, EA), each
    run by the trial loop and recorded by the MLflow recorder as a grid records them."""
    specs = [
        TrialSpec(approach, "Fp", evaluations=3000, batch_size=1000, seed=index)
        for index, approach in enumerate(("MAP-ST", "MAP-LIS", "EA"))
    ]
    return record_trials(tmp_path_factory.mktemp("explore"), GRID, specs)


def _view(uri: str, run_id: str, approach: str, tmp_path: Path, drawn=None) -> tuple:
    table = RunStore(uri).repertoire(run_id, tmp_path)
    trial = TrialRun(run_id, f"{approach}/Fp/00", approach, "Fp", "paper", 40)
    return table, repertoire_view(table, trial, drawn)


def test_view_holds_every_cell_with_its_checks_and_drawing(store, tmp_path):
    uri, runs = store
    table, view = _view(uri, runs["MAP-ST"], "MAP-ST", tmp_path)
    assert view["descriptors"] == ["mean_beam_length", "depth", "drive_size", "moving_share"]
    assert view["resolution"] == 10
    cells = view["cells"]
    assert len(cells) == len(table) > 50
    losses = [c["l"] for c in cells]
    assert losses == sorted(losses)
    by_cell = table.set_index("cell")
    genomes = np.stack([by_cell.loc[c["c"], "genome"] for c in cells]).astype(float)
    batch = decode(genomes, "paper")
    motion = simulate(batch, 40)
    checks = physical_checks(batch, motion)
    for i, cell in enumerate(cells):
        row = by_cell.loc[cell["c"]]
        assert cell["b"] == [int(row[f"bin_{d}"]) for d in range(4)]
        assert cell["l"] == pytest.approx(row["loss"], abs=1e-4)
        k = cell["k"]
        assert k[0] == int(checks.turns_fully[i]) and k[1] == int(checks.buildable[i])
        assert k[3] == checks.toggle_passages[i]
        assert k[5] == pytest.approx(checks.size_modules[i, 0], abs=0.05)
        g = cell["g"]
        n_beams = int(batch.n_beams[i])
        assert [m[:2] for m in g["m"]] == [
            [int(batch.beam_start[i, b]), int(batch.beam_end[i, b])] for b in range(n_beams)
        ]
        assert [m[4] for m in g["m"]] == [max(round(v), 1) for v in batch.beam_length[i, :n_beams]]
        foot = motion.positions[i, motion.foot[i]]
        drawn = np.array(g["f"], dtype=float)  # None: NaN
        assert np.allclose(drawn.T, foot, atol=0.051, equal_nan=True)
    _, few = _view(uri, runs["MAP-ST"], "MAP-ST", tmp_path / "few", drawn=5)
    assert [c["g"] is not None for c in few["cells"]] == [i < 5 for i in range(len(cells))]
    assert few["drawn"] == 5


def _page_views(path: Path) -> list[dict]:
    text = path.read_text(encoding="utf-8")
    blobs = re.findall(
        r'<script type="application/octet-stream" id="trial-\d+">([^<]+)</script>', text
    )
    return [json.loads(gzip.decompress(base64.b64decode(b))) for b in blobs]


def test_explore_writes_an_offline_page_and_logs_it_to_the_run(store, tmp_path, capsys):
    uri, runs = store
    out = tmp_path / "lis.html"
    assert main(["explore", runs["MAP-LIS"], "--tracking-uri", uri, "--out", str(out)]) == 0
    text = out.read_text(encoding="utf-8")
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", text)  # nothing to fetch
    views = _page_views(out)
    assert [v["run_id"] for v in views] == [runs["MAP-LIS"]]
    assert views[0]["drawn"] == len(views[0]["cells"])
    logged = [a.path for a in MlflowClient(uri).list_artifacts(runs["MAP-LIS"])]
    assert "explorer.html" in logged
    said = capsys.readouterr()
    assert f"logged as explorer.html to run {runs['MAP-LIS']}" in said.out
    assert f"[1/1] MAP-LIS/Fp/00 (run {runs['MAP-LIS']})" in said.err


def test_explore_a_grid_puts_every_repertoire_trial_on_one_page(store, tmp_path):
    uri, _ = store
    out = tmp_path / "grid.html"
    args = ["explore", GRID, "--tracking-uri", uri, "--out", str(out), "--drawn", "20"]
    assert main(args) == 0
    views = _page_views(out)
    assert [v["trial_key"] for v in views] == ["MAP-LIS/Fp/00", "MAP-ST/Fp/00"]  # study order
    assert all(
        v["drawn"] == 20 and sum(c["g"] is not None for c in v["cells"]) == 20 for v in views
    )
    client = MlflowClient(uri)
    parent = client.search_runs(
        [client.get_experiment_by_name("linkevo").experiment_id], "tags.`linkevo.kind` = 'grid'"
    )[0]
    assert "explorer.html" in [a.path for a in client.list_artifacts(parent.info.run_id)]


def test_explore_refuses_bad_input_before_writing(store, tmp_path, capsys):
    uri, runs = store
    out = tmp_path / "page.html"
    cases = [
        (
            [runs["EA"]],
            "is a EA trial, which keeps a population, not a repertoire; give a "
            "trial of MAP-WH, MAP-LIS, MAP-ST, MAP-AU, RANDOM or a grid id",
        ),
        (["ffff00001111"], f"known grids: {GRID}"),
        ([runs["MAP-ST"], "--drawn", "0"], "--drawn 0: give the number of cells to draw, >= 1"),
        (["it's"], '"it\'s" is neither a run id nor a grid id; allowed: letters, digits'),
    ]
    for extra, message in cases:
        assert main(["explore", *extra, "--tracking-uri", uri, "--out", str(out)]) == 2
        assert message in capsys.readouterr().err
    assert main(["explore", runs["MAP-ST"], "--tracking-uri", uri, "--out", str(tmp_path)]) == 2
    assert "allowed a .html file" in capsys.readouterr().err
    assert not out.exists()


@pytest.fixture(scope="module")
def browser():
    """A real headless Chromium."""
    with chromium() as driver:
        yield driver


def _text(browser, element_id: str) -> str:
    from selenium.webdriver.common.by import By

    return browser.find_element(By.ID, element_id).text


def test_page_in_chromium_hover_click_pin_filter_and_fold(store, tmp_path, browser):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    uri, runs = store
    out = tmp_path / "st.html"
    assert (
        main(["explore", runs["MAP-ST"], "--tracking-uri", uri, "--out", str(out), "--no-log"]) == 0
    )
    view = _page_views(out)[0]
    open_explorer(browser, out)
    worst, best = view["cells"][-1], view["cells"][0]
    point_at(browser, worst["c"])
    hovered = _text(browser, "hover-info")
    assert f"cell {worst['c']}: loss {worst['l']:.4f}" in hovered
    point_at(browser, best["c"], click=True)
    selected = _text(browser, "selected-info")
    assert f"cell {best['c']}: loss {best['l']:.4f}" in selected
    assert _text(browser, "pull-command") == f"linkevo pull {runs['MAP-ST']}:{best['c']}"
    sheet = browser.find_elements(By.CSS_SELECTOR, "#selected-info table tr")
    assert len(sheet) == 1 + len(best["g"]["m"])  # a row per beam
    browser.find_element(By.ID, "pin").click()
    point_at(browser, worst["c"], click=True)
    browser.find_element(By.ID, "pin").click()
    pinned = _text(browser, "pins")
    assert f"linkevo pull {runs['MAP-ST']}:{best['c']}" in pinned
    assert f"linkevo pull {runs['MAP-ST']}:{worst['c']}" in pinned

    n_buildable = sum(c["k"][1] for c in view["cells"])
    browser.find_element(By.ID, "f-buildable").click()
    passing = f"{n_buildable} of {len(view['cells'])} cells pass the filters"
    assert _text(browser, "passing") == passing
    browser.find_element(By.ID, "f-buildable").click()
    browser.find_element(By.ID, "f-size").send_keys("20")
    small = sum(max(c["k"][5], c["k"][6]) <= 20 for c in view["cells"])
    assert _text(browser, "passing").startswith(f"{small} of ")

    moved = next(c for c in view["cells"] if c["b"][0] != c["b"][3])
    where = "return window.explorer.cellCenter(arguments[0])"
    before = browser.execute_script(where, moved["c"])
    folds = browser.find_elements(By.CSS_SELECTOR, "select.fold")
    shown = [Select(f).first_selected_option.text for f in folds]
    # As the report folds a 4-D map: d3 and d1 along x (inner, outer), d2 and d0 up y.
    assert shown == ["moving_share", "drive_size", "depth", "mean_beam_length"]
    Select(folds[0]).select_by_visible_text("mean_beam_length")  # swaps with the tiles' y
    folds = browser.find_elements(By.CSS_SELECTOR, "select.fold")
    assert [Select(f).first_selected_option.text for f in folds] == [
        "mean_beam_length",
        "drive_size",
        "depth",
        "moving_share",
    ]
    assert browser.execute_script(where, moved["c"]) != before
    point_at(browser, moved["c"])  # the folded map still finds each cell
    assert f"cell {moved['c']}: loss {moved['l']:.4f}" in _text(browser, "hover-info")

    # A cell's real parts, or why none build it.
    named = [c for c in view["cells"] if "r" in c]
    assert [c["c"] for c in named] == [c["c"] for c in view["cells"] if c["k"][1]][:200]
    for cell in named[:3]:
        point_at(browser, cell["c"], click=True)
        said = _text(browser, "selected-info")
        if "x" in cell["r"]:
            assert f"Real parts: none build it ({cell['r']['x']})" in said
        else:
            number, name, count = cell["r"]["p"][0]
            assert "Real parts, one leg" in said and f"{count} × {name} ({number})" in said


def test_grid_page_in_chromium_picks_a_trial(store, tmp_path, browser):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    uri, runs = store
    out = tmp_path / "grid.html"
    assert main(["explore", GRID, "--tracking-uri", uri, "--out", str(out), "--no-log"]) == 0
    views = _page_views(out)
    open_explorer(browser, out)
    picker = Select(browser.find_element(By.ID, "trial"))
    assert [o.text.split(" ")[0] for o in picker.options] == ["MAP-LIS/Fp/00", "MAP-ST/Fp/00"]
    lowest = [min(c["l"] for c in v["cells"] if c["l"] is not None) for v in views]
    best = int(np.argmin(lowest))  # the page opens on the trial holding the lowest loss
    assert picker.first_selected_option.text.startswith(views[best]["trial_key"])
    _wait_for(browser, "summary", runs[views[best]["approach"]])
    legend = _text(browser, "legend")
    assert "2nd to 98th percentile" in legend and f"all: {lowest[best]:.4f} to" in legend
    other = 1 - best
    picker.select_by_index(other)
    _wait_for(browser, "summary", runs[views[other]["approach"]])
    cell = views[other]["cells"][0]
    point_at(browser, cell["c"], click=True)
    said = _text(browser, "selected-info")
    assert f"{views[other]['trial_key']}, cell {cell['c']}: loss {cell['l']:.4f}" in said


def _wait_for(browser, element: str, text: str) -> None:
    deadline = time.monotonic() + 10
    while text not in _text(browser, element):
        assert time.monotonic() < deadline, f"{text!r} never showed in #{element}"
        time.sleep(0.05)


def test_the_logged_page_works_inside_the_mlflow_ui(store, tmp_path, browser, mlflow_server):
    from selenium.webdriver.common.by import By

    uri, runs = store
    source = MlflowClient(uri).get_run(runs["MAP-LIS"])
    served = MlflowClient(mlflow_server)
    experiment = ensure_experiment(mlflow_server)
    run_id = served.create_run(experiment, tags=source.data.tags).info.run_id
    served.log_batch(run_id, params=[Param(k, v) for k, v in source.data.params.items()])
    table = RunStore(uri).repertoire(runs["MAP-LIS"], tmp_path)
    table.to_parquet(tmp_path / "repertoire.parquet")
    served.log_artifact(run_id, str(tmp_path / "repertoire.parquet"))
    out = tmp_path / "page.html"
    assert main(["explore", run_id, "--tracking-uri", mlflow_server, "--out", str(out)]) == 0
    cell = _page_views(out)[0]["cells"][0]

    browser.get(f"{mlflow_server}/#/experiments/{experiment}/runs/{run_id}/artifacts/explorer.html")
    deadline = time.monotonic() + 60
    while not browser.find_elements(By.TAG_NAME, "iframe"):  # MLflow's HTML artefact view
        assert time.monotonic() < deadline, "the MLflow UI did not show explorer.html"
        time.sleep(0.2)
    browser.switch_to.frame(browser.find_element(By.TAG_NAME, "iframe"))
    try:
        while not browser.execute_script("return !!(window.explorer && window.explorer.ready)"):
            assert time.monotonic() < deadline, "the page did not run inside the MLflow UI"
            time.sleep(0.1)
        browser.execute_script("document.getElementById('map').scrollIntoView()")
        point_at(browser, cell["c"], click=True)
        assert _text(browser, "pull-command") == f"linkevo pull {run_id}:{cell['c']}"
    finally:
        browser.switch_to.default_content()


def test_a_walk_beyond_the_level_body_bound_or_sliding_is_flagged_in_the_view(store, tmp_path):
    from linkevo.sim.robot.walk_rows import walk_map_frame

    uri, runs = store
    table = RunStore(uri).repertoire(runs["MAP-LIS"], tmp_path)
    cells = table["cell"].to_numpy()[:2]
    rows = [
        {
            "cell": int(c),
            "floor": "flat",
            "status": "walked",
            "mean_distance_cm": d,
            "breaks": False,
            "reason": "",
            "leg": "LEGO build",
            "bound_cm": 100.0,
            "torque_p95_of_stall": 0.3,
            "pin_force_p99_n": 10.0,
            "foot_slip_mm_s": slip,
            "seconds": 10.0,
        }
        for c, d, slip in zip(cells, (80.0, 130.0), (5.0, 100.0), strict=True)
    ]
    trial = TrialRun(runs["MAP-LIS"], "MAP-LIS/Fp/00", "MAP-LIS", "Fp", "paper", 40)
    view = repertoire_view(table, trial, 0, walk_map_frame(rows))
    walks = {c["c"]: c["w"][0] for c in view["cells"] if c["c"] in set(cells.tolist())}
    assert walks[int(cells[0])] == [80.0, 0, "", 0, 0]
    # 130 cm against a 100-cm bound, its feet slipping at 100 of the body's 130 mm/s
    assert walks[int(cells[1])] == [130.0, 0, "", 1, 1]
