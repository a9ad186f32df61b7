"""`linkevo walkmap` on a real store, a real local Ray instance and the real engine: the walk
map logged to the trial's run, `--resume`, bad input, and the explorer's walking layer in a
real headless Chromium."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from mlflow.tracking import MlflowClient

from linkevo.orchestrator.cli import main
from linkevo.orchestrator.repertoire_walks import Selection, run_in_process, top_walkers, walk_map
from linkevo.sim.robot.walk_map import build_cells
from linkevo.workers.store.runs import RunStore
from linkevo.workers.trial_spec import TrialSpec
from tests.helpers.browser import chromium, open_explorer, point_at
from tests.helpers.trials import record_trials

GRID = "0a0b0c0d0e0f"
SECONDS = "2"


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """A real sqlite store with real MAP-LIS, MAP-WH and EA trials of a grid, run by the
    trial loop and recorded as a grid records them."""
    specs = [
        TrialSpec(approach, "Fp", evaluations=4000, batch_size=1000, seed=3)
        for approach in ("MAP-LIS", "MAP-WH", "EA")
    ]
    return record_trials(tmp_path_factory.mktemp("walkmap"), GRID, specs)


@pytest.fixture(scope="module")
def lis_map(store, ray_local, tmp_path_factory) -> tuple[pd.DataFrame, str]:
    """MAP-LIS's walk map of its best 8 cells (a few of them build with real parts), made by
    the command: (its rows, what the command printed). The tests that read or extend a walk
    map start from it."""
    import contextlib
    import io

    uri, runs = store
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(
            [
                "walkmap",
                runs["MAP-LIS"],
                "--cells",
                "best:8",
                "--seconds",
                SECONDS,
                "--tracking-uri",
                uri,
            ]
        )
    assert code == 0
    return _walk_map(uri, runs["MAP-LIS"], tmp_path_factory.mktemp("lis-map")), printed.getvalue()


def _walk_map(uri: str, run_id: str, tmp: Path) -> pd.DataFrame:
    path = MlflowClient(uri).download_artifacts(run_id, "walkmap.parquet", str(tmp))
    return pd.read_parquet(path)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (
            ["--floor", "ice"],
            "--floor: invalid choice: 'ice' (choose from 'flat', 'carpet', 'both')",
        ),
        (["--cells", "best:0"], "--cells 'best:0': allowed buildable, all, best:K"),
        (["--cells", "most"], "--cells 'most'"),
        (["--seconds", "0"], "--seconds: '0' is not allowed: a number of seconds in (0, 600]"),
        (["--resume", "--restart"], "--restart: not allowed with argument --resume"),
    ],
)
def test_bad_input_is_refused_before_any_work(store, args, message, capsys):
    uri, runs = store
    client = MlflowClient(uri)
    before = [(a.path, a.file_size) for a in client.list_artifacts(runs["MAP-LIS"])]
    assert main(["walkmap", runs["MAP-LIS"], "--tracking-uri", uri, *args]) == 2
    assert message in capsys.readouterr().err
    assert [(a.path, a.file_size) for a in client.list_artifacts(runs["MAP-LIS"])] == before


def test_a_population_trial_has_no_map_to_walk(store, capsys):
    uri, runs = store
    assert main(["walkmap", runs["EA"], "--tracking-uri", uri]) == 2
    assert "keeps a population, not a repertoire" in capsys.readouterr().err


def test_walkmap_walks_the_chosen_cells_on_both_floors_and_logs_the_map(store, lis_map, tmp_path):
    uri, runs = store
    run_id = runs["MAP-LIS"]
    frame, printed = lis_map
    client = MlflowClient(uri)
    store = RunStore(uri)
    trial = store.repertoire_trial(run_id)
    table = store.repertoire(run_id, tmp_path / "rep")
    expected = Selection.parse("best:8").choose(table, trial.mode)["cell"].tolist()
    assert sorted(frame["cell"].unique()) == sorted(expected)
    assert len(frame) == 16 and set(frame["floor"]) == {"flat", "carpet"}
    assert {"bin_0", "bin_1", "mean_distance_cm", "breaks", "reason"} <= set(frame.columns)
    walked = frame[frame["status"] == "walked"]
    assert len(walked) >= 2 and np.isfinite(walked["mean_distance_cm"]).all()
    names = [a.path for a in client.list_artifacts(run_id)]
    assert "walkmap.png" in names
    for floor in ("flat", "carpet"):
        sound = walked[(walked["floor"] == floor) & ~walked["breaks"]]
        if len(sound):
            history = client.get_metric_history(run_id, f"walk_best_cm_{floor}")
            assert history[0].value == pytest.approx(sound["mean_distance_cm"].max())
            assert f"  {floor}: " in printed
            beyond = int((sound["mean_distance_cm"] > sound["bound_cm"]).sum())
            assert f"{len(sound)} walk ({beyond} beyond the level-body bound)" in printed
            here = walked[walked["floor"] == floor]
            frail = int(here["reason"].str.contains("frail:").sum())
            assert f"{len(here) - len(sound)} break ({frail} frail)" in printed
    # The top walkers, with their legs' shapes: the cells sound on both floors, best first.
    walkers = top_walkers(frame, table, trial.mode)
    both = walked[~walked["breaks"]].groupby("cell")["floor"].nunique()
    assert [w["cell"] for w in walkers] == [w["cell"] for w in walkers if both[w["cell"]] == 2]
    worst = [min(w["credited_cm"].values()) for w in walkers]
    assert worst == sorted(worst, reverse=True) and len(walkers) == min(3, int((both == 2).sum()))
    for w in walkers:
        assert f"    cell {w['cell']}: flat {w['credited_cm']['flat']:.1f}" in printed
        assert f"crank share {w['shape']['crank_share']:.2f}" in printed


def test_walkmap_refuses_to_overwrite_and_resume_walks_only_what_is_missing(
    store, lis_map, ray_local, tmp_path, capsys
):
    uri, runs = store
    run_id = runs["MAP-LIS"]
    before = _walk_map(uri, run_id, tmp_path / "before")
    assert main(["walkmap", run_id, "--cells", "best:10", "--tracking-uri", uri]) == 2
    assert "already has a walk map; add --resume" in capsys.readouterr().err

    store = RunStore(uri)
    walked_now: list[int] = []

    def counted(work, items):
        if work is build_cells:
            walked_now.extend(int(c) for b in items for c in b.cells)
        return run_in_process(work, items)

    after = walk_map(
        store,
        store.repertoire_trial(run_id),
        counted,
        floors=("flat", "carpet"),
        selection=Selection.parse("best:10"),
        resume=True,
        seconds=float(SECONDS),
    ).frame
    assert len(walked_now) == 2 and not set(walked_now) & set(before["cell"])
    assert len(after) == 20
    old = after[after["cell"].isin(before["cell"])].sort_values(["floor", "cell"])
    pd.testing.assert_frame_equal(
        old.reset_index(drop=True)[list(before.columns)],
        before.sort_values(["floor", "cell"]).reset_index(drop=True),
    )
    assert len(_walk_map(uri, run_id, tmp_path / "after")) == 20


def test_the_explorer_colours_by_distance_and_filters_on_walking(store, lis_map, tmp_path):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    uri, runs = store
    run_id = runs["MAP-LIS"]
    frame = _walk_map(uri, run_id, tmp_path)
    if frame.empty:  # the walk map of the test above
        pytest.fail("no walk map")
    out = tmp_path / "page.html"
    assert main(["explore", run_id, "--tracking-uri", uri, "--out", str(out), "--no-log"]) == 0
    walked = frame[(frame["status"] == "walked") & (frame["floor"] == "flat")]
    cell = int(walked.sort_values("mean_distance_cm").iloc[-1]["cell"])
    distance = float(walked.set_index("cell").loc[cell, "mean_distance_cm"])
    with chromium() as browser:
        open_explorer(browser, out)
        assert browser.find_element(By.ID, "walking").is_displayed()
        colour = Select(browser.find_element(By.ID, "colour-by"))
        assert [o.text for o in colour.options] == ["loss", "distance, flat", "distance, carpet"]
        colour.select_by_visible_text("distance, flat")
        assert "distance on flat" in browser.find_element(By.ID, "legend").text

        point_at(browser, cell)
        hovered = browser.find_element(By.ID, "hover-info").text
        assert f"cell {cell}:" in hovered
        assert f"flat: {distance:.1f} cm" in hovered

        least = float(np.median(walked["mean_distance_cm"]))
        browser.find_element(By.ID, "f-walk").send_keys(f"{least:.1f}")
        expected = int((walked["mean_distance_cm"].round(1) >= round(least, 1)).sum())
        total = browser.execute_script("return window.explorer.view().cells.length")
        passing = browser.find_element(By.ID, "passing").text
        assert passing == f"{expected} of {total} cells pass the filters"
        browser.find_element(By.ID, "f-sound").click()
        sound = int(
            ((walked["mean_distance_cm"].round(1) >= round(least, 1)) & ~walked["breaks"]).sum()
        )
        assert browser.find_element(By.ID, "passing").text.startswith(f"{sound} of ")


def test_pull_prints_and_writes_a_walked_cells_simulated_walks(store, lis_map, tmp_path, capsys):
    import json

    uri, runs = store
    run_id = runs["MAP-LIS"]
    frame = _walk_map(uri, run_id, tmp_path / "map")
    walked = frame[(frame["status"] == "walked") & (frame["floor"] == "flat")].iloc[0]
    cell = int(walked["cell"])
    out = tmp_path / "pulled"
    assert main(["pull", f"{run_id}:{cell}", "--out", str(out), "--tracking-uri", uri]) == 0
    printed = capsys.readouterr().err
    assert f"simulated walk: flat {walked['mean_distance_cm']:.1f} cm in 2 s" in printed
    document = json.loads((out / "linkage.json").read_text())
    assert document["simulated_walk"]["flat"]["distance_cm"] == round(walked["mean_distance_cm"], 1)
    assert "Simulated walk: flat" in (out / "build_sheet.md").read_text()


def test_ctrl_c_keeps_the_walks_so_far_and_resume_completes_the_map(
    store, ray_local, tmp_path, capsys
):
    import os
    import re
    import select
    import shlex
    import signal
    import subprocess
    import sys

    uri, runs = store
    run_id = runs["MAP-WH"]
    linkevo = Path(sys.executable).parent / "linkevo"  # not on PATH: printed as its path
    args = [
        "walkmap",
        run_id,
        "--cells",
        "best:30",
        "--seconds",
        "1",
        "--floor",
        "flat",
        "--tracking-uri",
        uri,
    ]
    # An ignored SIGINT is inherited across exec; the walk map's Ctrl-C is what is tested, so
    # the command starts with the default disposition whatever an earlier test left here.
    proc = subprocess.Popen(
        [str(linkevo), *args],
        stderr=subprocess.PIPE,
        cwd=tmp_path,
        env={**os.environ, "PATH": "/usr/bin:/bin"},
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    seen, deadline = b"", time.monotonic() + 120
    while not re.search(rb"walking: .*\| ([1-9]|\d\d)/30 ", seen):  # walks done, most to do
        assert time.monotonic() < deadline and proc.poll() is None, seen.decode()[-500:]
        if select.select([proc.stderr], [], [], 0.5)[0]:
            seen += proc.stderr.read1(4096)
    proc.send_signal(signal.SIGINT)
    _, rest = proc.communicate(timeout=60)
    assert proc.returncode == 130
    printed = (seen + rest).decode()
    again = [
        run_id,
        "--floor",
        "flat",
        "--cells",
        "best:30",
        "--seconds",
        "1",
        "--tracking-uri",
        uri,
        "--resume",
    ]
    assert f"Complete the map with:  {linkevo} walkmap {shlex.join(again)}\n" in printed, printed
    partial = _walk_map(uri, run_id, tmp_path / "partial")
    assert 1 <= len(partial) < 30

    assert main(["walkmap", *again]) == 0  # the printed line, as the user runs it
    assert main(["walkmap", *again]) == 0  # a complete map: said so, nothing walked
    assert "the walk map is complete" in capsys.readouterr().out
    complete = _walk_map(uri, run_id, tmp_path / "complete")
    assert len(complete) == 30 and complete["cell"].is_unique
    kept = complete.set_index("cell").loc[partial["cell"], "mean_distance_cm"].to_numpy()
    assert np.array_equal(kept, partial["mean_distance_cm"].to_numpy(), equal_nan=True)


def test_a_second_walk_map_of_one_run_is_refused_and_no_row_is_lost(store, ray_local, tmp_path):
    import subprocess
    import sys

    uri, runs = store
    run_id = runs["MAP-WH"]
    first = [
        sys.executable,
        "-m",
        "linkevo.orchestrator",
        "walkmap",
        run_id,
        "--restart",
        "--cells",
        "best:12",
        "--floor",
        "flat",
        "--seconds",
        "1",
        "--tracking-uri",
        uri,
    ]
    proc = subprocess.Popen(first, stderr=subprocess.PIPE, stdout=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not _holds_lease(uri, run_id):
        assert time.monotonic() < deadline and proc.poll() is None, "the first never started"
        time.sleep(0.2)
    second = subprocess.run(
        [*first[:5], "--resume", "--floor", "carpet", "--tracking-uri", uri],
        capture_output=True,
        text=True,
        timeout=120,
    )
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err.decode()[-2000:]
    assert second.returncode == 2, second.stderr
    assert (
        f"the walk map of run {run_id} (MAP-WH/Fp/00) is being made by another linkevo "
        f"walkmap pid {proc.pid}" in second.stderr
    )
    assert "Traceback" not in second.stderr
    frame = _walk_map(uri, run_id, tmp_path)
    assert len(frame) == 12 and set(frame["floor"]) == {"flat"}  # the first's, whole


def _holds_lease(uri: str, run_id: str) -> bool:
    from linkevo.workers.store import run_layout as layout

    tags = MlflowClient(uri).get_experiment_by_name("linkevo").tags
    return layout.lease_tag(f"walkmap.{run_id}") in tags


def _damaged(path: Path, how: str) -> Path:
    """Writes a damaged walk map, as a bad disk, a bad edit or another program would."""
    good = pd.DataFrame(
        {
            "cell": [1, 2],
            "floor": ["flat", "flat"],
            "status": ["walked", "walked"],
            "mean_distance_cm": [10.0, 20.0],
            "breaks": [False, False],
            "reason": ["", ""],
            "leg": ["LEGO build"] * 2,
            "bound_cm": [30.0, 30.0],
            "torque_p95_of_stall": [0.1, 0.1],
            "pin_force_p99_n": [5.0, 5.0],
            "seconds": [1.0, 1.0],
        }
    )
    if how == "empty":
        path.write_bytes(b"")
    elif how == "truncated":
        good.to_parquet(path)
        path.write_bytes(path.read_bytes()[:200])
    elif how == "random":
        path.write_bytes(np.random.default_rng(0).bytes(5000))
    elif how == "wrong columns":
        good.drop(columns=["breaks"]).to_parquet(path)
    elif how == "NaN distance":
        good.assign(mean_distance_cm=[np.nan, 20.0]).to_parquet(path)
    return path


@pytest.mark.parametrize(
    ("how", "problem"),
    [
        ("empty", "is not a readable parquet table"),
        ("truncated", "is not a readable parquet table"),
        ("random", "is not a readable parquet table"),
        ("wrong columns", "lacks the column(s) breaks"),
        ("NaN distance", "has walks that do not break but have no finite distance"),
    ],
)
def test_a_damaged_walk_map_is_refused_naming_the_file_its_run_and_the_remedy(
    store, tmp_path, how, problem, capsys
):
    uri, runs = store
    client = MlflowClient(uri)
    run_id = client.create_run(
        client.get_run(runs["MAP-LIS"]).info.experiment_id,
        tags=client.get_run(runs["MAP-LIS"]).data.tags,
    ).info.run_id
    table = RunStore(uri).repertoire(runs["MAP-LIS"], tmp_path / "rep")
    table.to_parquet(tmp_path / "repertoire.parquet")
    client.log_artifact(run_id, str(tmp_path / "repertoire.parquet"))
    client.log_artifact(run_id, str(_damaged(tmp_path / "walkmap.parquet", how)))
    cell = int(table["cell"].iloc[0])
    for command in (
        ["walkmap", run_id, "--resume"],
        ["explore", run_id, "--no-log", "--out", str(tmp_path / "page.html")],
        ["pull", f"{run_id}:{cell}", "--out", str(tmp_path / "pulled")],
    ):
        assert main([*command, "--tracking-uri", uri]) == 2, command
        err = capsys.readouterr().err
        assert f"walkmap.parquet of run {run_id} {problem}" in err, err
        assert f"linkevo walkmap {run_id} --restart" in err
    assert not (tmp_path / "page.html").exists() and not (tmp_path / "pulled").exists()


def test_a_missing_or_damaged_repertoire_is_refused_by_name(store, tmp_path, capsys):
    uri, runs = store
    client = MlflowClient(uri)
    source = client.get_run(runs["MAP-LIS"])
    bare = client.create_run(source.info.experiment_id, tags=source.data.tags).info.run_id
    for command in (["walkmap", bare], ["explore", bare, "--no-log"]):
        assert main([*command, "--tracking-uri", uri]) == 2
        err = capsys.readouterr().err
        assert f"run {bare} has no artefact 'repertoire.parquet'" in err and "Traceback" not in err
    table = RunStore(uri).repertoire(runs["MAP-LIS"], tmp_path / "rep")
    table.assign(genome=[np.full(56, 2.0)] * len(table)).to_parquet(tmp_path / "repertoire.parquet")
    client.log_artifact(bare, str(tmp_path / "repertoire.parquet"))
    assert main(["walkmap", bare, "--tracking-uri", uri]) == 2
    assert "has genomes that are not 56 genes in [0, 1)" in capsys.readouterr().err


def test_a_walking_grid_starts_from_a_walked_repertoire(store, lis_map, tmp_path, capsys):
    """`seed_from`: the walking trial's first batch is the earlier trial's walked cells,
    told with their walk-map rows (no walk); a run that cannot seed is refused first."""
    from linkevo.orchestrator.config import ConfigError
    from linkevo.orchestrator.driver import launch
    from tests.helpers.grid import tiny_grid

    uri, runs = store
    walked = _walk_map(uri, runs["MAP-LIS"], tmp_path / "map")  # as the tests before left it
    usable = walked[walked["status"] == "walked"].groupby("cell")["floor"].nunique()
    seeded_cells = set(usable[usable == 2].index)
    assert seeded_cells  # the map walked some cells on both floors
    grid = tiny_grid(
        tmp_path,
        approaches=["MAP-LIS"],
        fitnesses=["Fw"],
        trials=1,
        walks=6,
        walk_batch=8,
        evaluators_per_trial=0,
        trial_cpus=1,
        seed_from=runs["MAP-LIS"],
        tracking_uri=uri,
    )
    result = launch(grid, progress=False)
    assert not result.failed
    run_id = result.outcomes[0].run_id
    client = MlflowClient(uri)
    log = pd.read_parquet(client.download_artifacts(run_id, "walks.parquet", str(tmp_path)))
    first = log[log["iteration"] == 1]
    assert set(first["stage"]) == {"seeded"} and len(first) == len(seeded_cells)
    assert client.get_run(run_id).data.metrics["walks_reused"] == len(seeded_cells)
    history = client.get_metric_history(run_id, "walks")
    assert min(m.value for m in history) == 0  # the seeded batch walked nothing
    # A MAP-Elites trial without a walk map: in a store of its own, since the tests before
    # this one may have walked every map of the module's store.
    bare_uri, bare = record_trials(tmp_path / "bare", GRID, [TrialSpec("MAP-ST", "Fp", 1000, 500)])
    for seed_from, message, where in (
        (runs["EA"], "a MAP-Elites trial with a walk map", uri),
        (bare["MAP-ST"], "without walkmap.parquet", bare_uri),
    ):
        again = tiny_grid(
            tmp_path,
            approaches=["MAP-LIS"],
            fitnesses=["Fw"],
            trials=1,
            walks=6,
            seed_from=seed_from,
            tracking_uri=where,
        )
        with pytest.raises(ConfigError, match=message):
            launch(again, progress=False)


def test_a_walk_map_keeps_its_robot_and_refuses_to_resume_on_another(
    store, lis_map, tmp_path, capsys
):
    uri, runs = store
    run_id = runs["MAP-LIS"]
    tags = MlflowClient(uri).get_run(run_id).data.tags
    assert tags["walk_map_robot"] == "{}"  # walked on the study's robot
    heavy = tmp_path / "heavy.toml"
    shipped = (Path(__file__).parents[2] / "configs" / "hexapod.toml").read_text()
    heavy.write_text(shipped.replace("frame_mass_kg = 1.1", "frame_mass_kg = 2.5"))
    before = _walk_map(uri, run_id, tmp_path / "before")
    argv = [
        "walkmap",
        run_id,
        "--cells",
        "best:6",
        "--resume",
        "--config",
        str(heavy),
        "--tracking-uri",
        uri,
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err
    said = 'its walk map walked the robot {}, this one is {"physics": {"frame_mass_kg": 2.5}}'
    assert said in err
    assert "or --restart to walk the map anew" in err
    pd.testing.assert_frame_equal(_walk_map(uri, run_id, tmp_path / "after"), before)
