"""Tests of `linkevo report` on a real MLflow store holding a grid with a failed trial."""

from __future__ import annotations

import base64
import html
import io
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from mlflow.tracking import MlflowClient
from PIL import Image
from scipy.stats import mannwhitneyu

from linkevo.orchestrator.cli import main
from linkevo.orchestrator.report import build_report, load_grid
from linkevo.orchestrator.report import figures as fig
from linkevo.orchestrator.report.checks import checks_summary
from linkevo.orchestrator.report.findings import check_findings
from linkevo.orchestrator.report.html import table_html
from linkevo.orchestrator.report.stats import holm, pairwise_tests
from linkevo.orchestrator.report.verdicts import NOT_SHOWN, NOT_TESTABLE, REPRODUCED
from linkevo.sim import decode, simulate
from linkevo.sim.linkage.linkage_doc import from_document
from linkevo.sim.linkage.physical import physical_checks
from linkevo.workers.store.tables import fold_bins
from tests.helpers.report import GridSpec, write_grid

SPEC = GridSpec(
    grid_id="g0report",
    trials=6,
    failed=("MAP-WH/Fp/01",),
    missing=("EA/Fsl/02",),
)
"""4 approaches x 2 fitnesses x 6 trials; one trial failed, one never started."""


@pytest.fixture(scope="module")
def grid(tmp_path_factory):
    """The written grid and its report (built once for the module)."""
    folder = tmp_path_factory.mktemp("report")
    written = write_grid(folder / "store", SPEC)
    result = build_report(written.uri, SPEC.grid_id, folder / "out")
    return written, result


@pytest.fixture(scope="module")
def loaded(grid, tmp_path_factory):
    written, _ = grid
    return load_grid(written.uri, SPEC.grid_id, tmp_path_factory.mktemp("cache"))


def raw_best_losses(written) -> pd.DataFrame:
    """Returns each finished trial's best loss recomputed from its logged metric history."""
    client = MlflowClient(tracking_uri=written.uri)
    rows = []
    for key, run_id in written.run_ids.items():
        run = client.get_run(run_id)
        if run.info.status != "FINISHED":
            continue
        history = client.get_metric_history(run_id, "best_loss")
        approach, fitness, _ = key.split("/")
        rows.append((key, approach, fitness, min(m.value for m in history)))
    return pd.DataFrame(rows, columns=["trial_key", "approach", "fitness", "best_loss"])


def test_summary_table_equals_values_recomputed_from_raw_metrics(grid):
    written, result = grid
    raw = raw_best_losses(written)
    summary = pd.read_csv(result.out_dir / "best_loss_summary.csv")
    assert len(summary) == len(SPEC.approaches) * len(SPEC.fitnesses)
    for row in summary.itertuples():
        values = raw.best_loss[(raw.approach == row.approach) & (raw.fitness == row.fitness)]
        assert row.n_finished == len(values)
        q1, median, q3 = np.quantile(values, [0.25, 0.5, 0.75])
        assert row.median == pytest.approx(median, rel=1e-12)
        assert row.iqr == pytest.approx(q3 - q1, rel=1e-9, abs=1e-12)
        assert row.min == pytest.approx(values.min(), rel=1e-12)


def test_trials_csv_carries_the_common_grid_and_path_diversity_as_logged(grid):
    written, result = grid
    client = MlflowClient(tracking_uri=written.uri)
    trials = pd.read_csv(result.out_dir / "trials.csv").set_index("trial_key")
    finished = trials[trials.status == "FINISHED"]
    assert len(finished) > 0
    for key, row in finished.iterrows():
        logged = client.get_run(written.run_ids[key]).data.metrics
        for name in ("common_coverage", "common_qd_score", "path_diversity"):
            assert row[name] == pytest.approx(logged[name], rel=1e-12), (key, name)
    sizes = pd.read_csv(result.out_dir / "path_sizes.csv")
    assert len(sizes) == len(finished)
    assert (sizes["size"] == sizes[["width", "height"]].max(axis=1)).all()


def test_best_linkages_physical_checks_match_their_genomes(grid, loaded):
    _, result = grid
    table = pd.read_csv(result.out_dir / "best_linkage_checks.csv")
    finished = loaded.finished()
    assert sorted(table.trial_key) == sorted(finished.trial_key)
    keyed = finished.set_index("trial_key")
    genomes = np.stack(
        [
            from_document(json.loads(Path(keyed.best_linkage[k]).read_text()))[0]
            for k in table.trial_key
        ]
    )
    batch = decode(genomes, "paper")
    checks = physical_checks(batch, simulate(batch))
    assert table.buildable.tolist() == checks.buildable.tolist()
    assert table.toggle_passages.tolist() == checks.toggle_passages.tolist()
    assert np.allclose(table.size_modules, checks.size_modules.max(axis=1))
    page = result.html.read_text()
    assert "Can the best linkages be built?" in page
    summary = checks_summary(table)
    assert summary.buildable.sum() == checks.buildable.sum()
    assert table_html(summary) in page


def test_failed_and_missing_trials_are_marked_not_counted(grid):
    _, result = grid
    trials = pd.read_csv(result.out_dir / "trials.csv").set_index("trial_key")
    assert trials.loc["MAP-WH/Fp/01", "status"] == "FAILED"
    assert "boom" in trials.loc["MAP-WH/Fp/01", "error"]
    assert trials.loc["EA/Fsl/02", "status"] == "MISSING"
    assert np.isnan(trials.loc["MAP-WH/Fp/01", "best_loss"])
    summary = result.summary.set_index(["fitness", "approach"])
    assert summary.loc[("Fp", "MAP-WH"), ["n_finished", "n_failed"]].tolist() == [5, 1]
    assert summary.loc[("Fsl", "EA"), ["n_finished", "n_missing"]].tolist() == [5, 1]
    page = result.html.read_text()
    assert "MAP-WH/Fp/01" in page and "MISSING" in page


def test_pairwise_tests_match_scipy_on_the_raw_best_losses(grid):
    written, result = grid
    raw = raw_best_losses(written)
    tests = pd.read_csv(result.out_dir / "pairwise_tests.csv")
    k = len(SPEC.approaches)
    assert len(tests) == len(SPEC.fitnesses) * k * (k - 1) // 2
    for fitness, block in tests.groupby("fitness"):
        p_values = []
        for row in block.itertuples():
            x = raw.best_loss[(raw.fitness == fitness) & (raw.approach == row.approach_a)]
            y = raw.best_loss[(raw.fitness == fitness) & (raw.approach == row.approach_b)]
            expected = mannwhitneyu(x, y, alternative="two-sided")
            assert row.u == pytest.approx(expected.statistic)
            assert row.p == pytest.approx(expected.pvalue, rel=1e-9)
            assert row.a12 == pytest.approx(expected.statistic / (len(x) * len(y)))
            p_values.append(expected.pvalue)
        assert block.p_holm.to_numpy() == pytest.approx(holm(np.array(p_values)))


def test_holm_adjusts_known_p_values():
    adjusted = holm(np.array([0.01, 0.04, 0.03, 0.005]))
    # sorted 0.005, 0.01, 0.03, 0.04 -> x4, x3, x2, x1 = 0.02, 0.03, 0.06, 0.04 -> running max
    assert adjusted == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert holm(np.array([0.5, 0.6])) == pytest.approx([1.0, 1.0])


def test_a12_and_u_agree_with_scipy_on_known_data():
    x = np.array([1.0, 2.0, 3.0, 3.0, 7.0])
    y = np.array([2.0, 3.0, 4.0, 5.0])
    trials = pd.DataFrame(
        {
            "approach": ["EA"] * 5 + ["MAP-WH"] * 4,
            "fitness": "Fp",
            "status": "FINISHED",
            "best_loss": np.concatenate([x, y]),
        }
    )
    row = pairwise_tests(trials).iloc[0]
    expected = mannwhitneyu(x, y, alternative="two-sided")
    assert row.u == expected.statistic
    assert row.p == pytest.approx(expected.pvalue)
    # pairs x > y: 3>2, 3>2, 7>all four = 6; ties x == y: 2=2, 3=3 twice = 3 -> (6 + 1.5) / 20
    assert row.a12 == pytest.approx(7.5 / 20)
    assert row.p_holm == pytest.approx(row.p)
    assert not row.significant and row.better == ""  # no winner named without significance
    apart = trials.assign(best_loss=np.concatenate([x, y]) + np.repeat([0.0, 10.0], [5, 4]))
    wide = pd.concat([apart, apart.assign(best_loss=apart.best_loss + 0.5)], ignore_index=True)
    row = pairwise_tests(wide).iloc[0]
    assert row.significant and row.better == "EA"


def test_each_figure_has_its_panels_and_labels(loaded):
    box = fig.best_loss_figure(loaded).figure
    assert [ax.get_title() for ax in box.axes] == ["F_p", "F_sl"]
    ticks = [t.get_text() for t in box.axes[0].get_xticklabels()]
    assert ticks[0].startswith("EA\nn=6") and "MAP-WH\nn=5\n1 not finished" in ticks

    maps = fig.repertoire_maps_figure(loaded).figure
    images = [ax for ax in maps.axes if ax.images]
    assert [ax.get_title().split(":")[0] for ax in images] == [
        "MAP-WH, F_p",
        "MAP-WH, F_sl",
        "MAP-ST, F_p",
        "MAP-ST, F_sl",
    ]
    assert images[0].get_xlabel() == "width (bin)" and images[0].get_ylabel() == "height (bin)"
    assert "mean_beam_length (outer bins)" in images[2].get_ylabel()
    assert "moving_share (inner" in images[2].get_xlabel()
    assert images[2].images[0].get_array().shape == (100, 100)

    paths = fig.path_maps_figure(loaded, "Fp").figure
    titled = [ax.get_title().split(":")[0] for ax in paths.axes if ax.get_title()]
    assert titled == ["MAP-WH, F_p", "MAP-ST, F_p", "EA, F_p", "NSGA-II, F_p"]
    assert paths.axes[-1].get_ylabel() == fig.LOSS_LABEL  # the one shared colour bar
    ea = next(ax for ax in paths.axes if ax.get_title().startswith("EA"))
    assert len(ea.collections[0].get_segments()) >= fig.STRIP_PATHS  # failed angles: gaps
    assert len(ea.texts) == fig.STRIP_PATHS

    conv = fig.convergence_figure(loaded).figure
    titles = [ax.get_title() for ax in conv.axes]
    measures = [name for _, name in fig.CONVERGENCE_METRICS]
    assert titles == [f"{m}, {f}" for m in measures for f in ("F_p", "F_sl")]
    assert [ax.get_xlabel() for ax in conv.axes[-2:]] == ["evaluations"] * 2
    legend = [t.get_text() for t in conv.legends[0].get_texts()]
    assert legend == [
        "EA",
        "NSGA-II",
        "MAP-WH",
        "MAP-ST",
        "band: 25th-75th percentile of the trials",
    ]
    conv.canvas.draw()
    ticks = [t.get_text() for t in conv.axes[-1].get_xticklabels() if t.get_text()]
    assert ticks and all(t == "0" or t.endswith("k") for t in ticks), ticks
    for figure in (maps, paths, conv):  # every figure says which study it shows
        assert "paper mode" in figure.get_suptitle() and "evaluations per trial" in (
            figure.get_suptitle()
        )


def test_repertoire_map_holds_the_best_loss_per_cell_over_trials(loaded):
    trials = loaded.finished()
    chosen = trials[(trials.approach == "MAP-ST") & (trials.fitness == "Fsl")]
    archives = pd.concat([pd.read_parquet(p) for p in chosen.archive], ignore_index=True)
    expected = archives.groupby(["bin_0", "bin_1", "bin_2", "bin_3"]).loss.min()
    maps = fig.repertoire_maps_figure(loaded).figure
    panel = next(ax for ax in maps.axes if ax.get_title().startswith("MAP-ST, F_sl"))
    image = panel.images[0].get_array()
    assert int((~image.mask).sum()) == len(expected)
    for (b0, b1, b2, b3), loss in expected.items():
        assert image[b0 * 10 + b2, b1 * 10 + b3] == pytest.approx(loss)


def test_path_maps_take_the_best_path_per_downsampled_region(loaded):
    trial = loaded.finished().query("approach == 'MAP-WH' and fitness == 'Fsl'")
    trial = trial.loc[trial.best_loss.idxmin()]
    archive = pd.read_parquet(trial.archive)
    chosen = fig.select_paths(archive, "MAP-WH")
    regions = archive.assign(row=archive.bin_0 // 20, col=archive.bin_1 // 20)
    expected = regions.groupby(["row", "col"]).loss.min()
    got = chosen.set_index(["row", "col"]).loss.sort_index()
    assert got.to_numpy() == pytest.approx(expected.sort_index().to_numpy())


def test_fold_bins_nests_the_inner_dimensions_in_blocks():
    rows, cols, side = fold_bins(np.array([[1, 2, 3, 4], [9, 9, 9, 9]]), 10)
    assert (rows.tolist(), cols.tolist(), side) == ([13, 99], [24, 99], 100)
    with pytest.raises(ValueError, match="3-D"):
        fold_bins(np.zeros((1, 3), dtype=int), 10)


def test_findings_are_checked_with_their_numbers(grid, loaded):
    _, result = grid
    verdicts = {f.claim: f for f in result.findings}
    beats_ea = verdicts["With F_p, the MAP-Elites approaches beat the EA (Results)."]
    assert beats_ea.verdict == REPRODUCED
    assert "MAP-WH median" in beats_ea.evidence and "Holm p" in beats_ea.evidence
    assert verdicts[
        "With F_p, the MAP-Elites approaches slightly beat NSGA-II (Results)."
    ].verdict == (REPRODUCED)
    fsl = result.tests[result.tests.fitness == "Fsl"]
    similar = verdicts["With F_sl, all approaches perform similarly (Results)."]
    assert similar.verdict in (NOT_SHOWN, REPRODUCED) or fsl.significant.any()
    assert "pairs" in similar.evidence
    findings_csv = pd.read_csv(result.out_dir / "findings.csv")
    assert findings_csv.verdict.tolist() == [f.verdict for f in result.findings]
    assert findings_csv.number.astype(str).tolist() == [f.number for f in result.findings]
    trials = pd.read_csv(result.out_dir / "trials.csv")
    assert {"stagnation", "descriptor_correlation", "front_size"} <= set(trials.columns)
    sizes = pd.read_csv(result.out_dir / "path_sizes.csv")
    again = check_findings(trials, sizes, result.tests, loaded.config.get("evaluations"))
    assert [f.verdict for f in again] == [f.verdict for f in result.findings]
    without_ea = pairwise_tests(loaded.trials[loaded.trials.approach != "EA"])
    assert check_findings(trials, sizes, without_ea, None)[0].verdict == NOT_TESTABLE


def test_html_is_self_contained_and_report_is_logged_to_the_parent_run(grid):
    written, result = grid
    page = result.html.read_text()
    pngs = page.split("data:image/png;base64,")[1:]
    assert len(pngs) == 5
    for chunk in pngs:
        Image.open(io.BytesIO(base64.b64decode(chunk.split("'", 1)[0]))).verify()
    assert "src='http" not in page and 'src="http' not in page
    for name in ("best_loss", "repertoire_maps", "paths_Fp", "paths_Fsl", "convergence"):
        assert (result.out_dir / f"{name}.pdf").read_bytes().startswith(b"%PDF")
        with Image.open(result.out_dir / f"{name}.png") as image:
            assert image.size[0] > 300
    client = MlflowClient(tracking_uri=written.uri)
    logged = {Path(a.path).name for a in client.list_artifacts(written.parent_run_id, "report")}
    assert {f.name for f in result.files} <= logged


def test_a_cell_with_only_failed_trials_still_reports(tmp_path):
    spec = GridSpec(
        grid_id="g0broken",
        approaches=("EA", "MAP-LIS"),
        fitnesses=("Fp",),
        trials=2,
        failed=("MAP-LIS/Fp/00", "MAP-LIS/Fp/01"),
    )
    written = write_grid(tmp_path / "store", spec)
    result = build_report(written.uri, None, tmp_path / "out", log_to_mlflow=False)
    row = result.summary.set_index("approach").loc["MAP-LIS"]
    assert row.n_finished == 0 and row.n_failed == 2 and np.isnan(row["median"])
    assert result.tests.empty
    assert (tmp_path / "out" / "best_loss.png").is_file()
    assert "not finished" in result.html.read_text() or "did not finish" in result.html.read_text()
    maps = fig.repertoire_maps_figure(load_grid(written.uri, "g0broken", tmp_path / "cache")).figure
    assert [ax.get_title() for ax in maps.axes if ax.get_title()] == [
        "MAP-LIS, F_p: no finished trial\n0 of 2 trials; 2 failed or missing"
    ]


def test_cli_reports_latest_grid_and_names_unknown_grids(grid, tmp_path, capsys):
    written, _ = grid
    out = tmp_path / "cli"
    argv = ["report", "--latest", "--tracking-uri", written.uri, "--out", str(out), "--no-log"]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert f"grid {SPEC.grid_id}" in printed and "[reproduced]" in printed
    assert (out / "report.html").is_file()
    assert main(["report", "nope", "--tracking-uri", written.uri, "--no-log"]) == 2
    err = capsys.readouterr().err
    assert "'nope'" in err and SPEC.grid_id in err
    assert main(["report", "a'b", "--tracking-uri", written.uri, "--no-log"]) == 2
    assert 'grid id "a\'b" is invalid' in capsys.readouterr().err
    assert main(["report", "--latest", "--tracking-uri", f"sqlite:///{tmp_path}/x.db"]) == 2
    assert "no MLflow store at" in capsys.readouterr().err


def test_a_grown_grid_is_answered_at_its_first_trials_too(grid, tmp_path, capsys):
    written, full = grid
    out = tmp_path / "first2"
    argv = ["report", SPEC.grid_id, "--tracking-uri", written.uri, "--trials", "2"]
    assert main([*argv, "--out", str(out)]) == 0
    assert "logged under report-first2/" in capsys.readouterr().out
    trials = pd.read_csv(out / "trials.csv")
    assert set(trials.trial_index) == {0, 1}
    summary = pd.read_csv(out / "best_loss_summary.csv")
    assert (
        summary.n_finished.max() <= 2 < pd.read_csv(full.out_dir / "trials.csv").trial_index.max()
    )
    client = MlflowClient(tracking_uri=written.uri)
    logged = {a.path for a in client.list_artifacts(written.parent_run_id, "report-first2")}
    assert "report-first2/trials.csv" in logged
    assert main([*argv[:-1], "0"]) == 2
    assert "--trials 0 is invalid; allowed: an integer >= 1" in capsys.readouterr().err


def test_a_grid_below_the_study_budget_is_a_pipeline_check_without_verdicts(tmp_path):
    spec = GridSpec(grid_id="g0small", approaches=("EA", "MAP-LIS"), trials=3, budget=1500)
    written = write_grid(tmp_path / "store", spec)
    result = build_report(written.uri, spec.grid_id, tmp_path / "out", log_to_mlflow=False)
    judged = "not judged: a pipeline check (1,500 of the study's 726,750 evaluations per trial)"
    assert result.findings and all(f.verdict == judged for f in result.findings)
    page = result.html.read_text()
    assert "class='text reproduced'" not in page and page.count(html.escape(judged)) == len(
        result.findings
    )


def test_a_hostile_grid_id_tag_never_names_a_folder(tmp_path, capsys, monkeypatch):
    hostile = "../../../EVIL_OUT"
    spec = GridSpec(grid_id=hostile, approaches=("EA",), fitnesses=("Fp",), trials=1)
    written = write_grid(tmp_path / "store", spec)
    work = tmp_path / "a" / "b" / "c"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    assert main(["report", "--latest", "--tracking-uri", written.uri, "--no-log"]) == 2
    err = capsys.readouterr().err
    assert "the grid_id tag of run" in err and repr(hostile) in err and "Traceback" not in err
    assert not (tmp_path / "EVIL_OUT").exists() and not list(work.iterdir())


def test_a_grid_without_trials_is_a_clear_error(tmp_path, capsys):
    written = write_grid(tmp_path / "store", GridSpec(grid_id="g0empty", approaches=()))
    assert main(["report", "g0empty", "--tracking-uri", written.uri, "--no-log"]) == 2
    assert "'g0empty' has no trial runs" in capsys.readouterr().err


def test_report_downloads_artefacts_through_a_tracking_server(mlflow_server, tmp_path):
    spec = GridSpec(grid_id="g0served", approaches=("EA", "MAP-LIS"), fitnesses=("Fp",), trials=2)
    written = write_grid(tmp_path / "files", spec, server_uri=mlflow_server)
    grid = load_grid(mlflow_server, None, tmp_path / "cache")
    assert grid.trials.archive.str.startswith(str(tmp_path / "cache")).all()
    result = build_report(mlflow_server, None, tmp_path / "out")
    raw = raw_best_losses(written).set_index("trial_key").best_loss
    got = pd.read_csv(result.out_dir / "trials.csv").set_index("trial_key").best_loss
    assert got.sort_index().to_numpy() == pytest.approx(raw.sort_index().to_numpy())
    client = MlflowClient(tracking_uri=mlflow_server)
    logged = {a.path for a in client.list_artifacts(written.parent_run_id, "report")}
    assert "report/report.html" in logged


def test_compare_puts_two_grids_side_by_side(tmp_path, capsys):
    """Two grids in one store, the second drawn with another seed: every shared cell is
    compared with the statistics recomputed here from the raw losses."""
    first = write_grid(tmp_path / "a", GridSpec(grid_id="g0first", seed=1))
    second = write_grid(tmp_path / "b", GridSpec(grid_id="g0second", seed=2), server_uri=first.uri)
    from linkevo.orchestrator.report.compare import compare_grids

    table, unlike = compare_grids(first.uri, "g0first", "g0second")
    assert len(table) == 4 * 2 and unlike == []  # the same budget, mode and trials
    for row in table.itertuples():
        x, y = (
            np.array(
                [
                    v
                    for k, v in w.final_best.items()
                    if k.startswith(f"{row.approach}/{row.fitness}/")
                ]
            )
            for w in (first, second)
        )
        assert (row.n_a, row.n_b) == (x.size, y.size)
        assert row.median_a == pytest.approx(np.median(x)) and row.median_b == pytest.approx(
            np.median(y)
        )
        assert row.difference == pytest.approx(np.median(y) - np.median(x))
        assert row.p == pytest.approx(mannwhitneyu(x, y, method="exact").pvalue)
    out = tmp_path / "cmp.csv"
    args = ["compare", "g0first", "g0second", "--tracking-uri", first.uri, "--out", str(out)]
    assert main(args) == 0
    assert "a = grid g0first, b = grid g0second" in capsys.readouterr().out
    assert pd.read_csv(out).shape == (8, 13)
    assert main(["compare", "g0first", "nope", "--tracking-uri", first.uri]) == 2
    assert "nope" in capsys.readouterr().err


def test_compare_reads_a_reports_trials_table(tmp_path, capsys):
    """A published grid (its report's trials.csv) compares as its store would."""
    first = write_grid(tmp_path / "a", GridSpec(grid_id="g0first", seed=1))
    write_grid(tmp_path / "b", GridSpec(grid_id="g0second", seed=2), server_uri=first.uri)
    from linkevo.orchestrator.report.compare import compare_grids

    csv = tmp_path / "trials.csv"
    load_grid(first.uri, "g0second", tmp_path / "cache").trials.to_csv(csv, index=False)
    expected = compare_grids(first.uri, "g0first", "g0second")[0]
    pd.testing.assert_frame_equal(compare_grids(first.uri, "g0first", str(csv))[0], expected)
    out = tmp_path / "cmp.csv"
    assert (
        main(["compare", "g0first", str(csv), "--tracking-uri", first.uri, "--out", str(out)]) == 0
    )
    assert pd.read_csv(out).p.to_numpy() == pytest.approx(expected.p.to_numpy())
    assert main(["compare", str(csv), str(tmp_path / "none.csv")]) == 2
    assert "none.csv' does not exist" in capsys.readouterr().err
    pd.DataFrame({"approach": ["EA"]}).to_csv(tmp_path / "bad.csv", index=False)
    assert main(["compare", str(csv), str(tmp_path / "bad.csv")]) == 2
    assert "lacks the columns fitness, status, best_loss" in capsys.readouterr().err


def test_compare_warns_when_the_grids_ran_differently(tmp_path, capsys):
    first = write_grid(tmp_path / "a", GridSpec(grid_id="g0first", seed=1))
    spec = GridSpec(grid_id="g0short", seed=2, trials=3, iterations=4)
    write_grid(tmp_path / "b", spec, server_uri=first.uri)
    assert main(["compare", "g0first", "g0short", "--tracking-uri", first.uri]) == 0
    err = capsys.readouterr().err
    assert "warning: EA Fp: 4 trials in a, 3 in b; the comparison is not like for like" in err
    assert "warning: EA Fp: a budget of 300 evaluations in a, 200 in b" in err


def test_a_report_that_fails_half_way_leaves_the_previous_one_whole(tmp_path, monkeypatch):
    from linkevo.orchestrator.report import build as report_build

    spec = GridSpec(grid_id="g0again", approaches=("EA", "MAP-LIS"), fitnesses=("Fp",), trials=2)
    written = write_grid(tmp_path / "store", spec)
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("the user's own file")
    first = build_report(written.uri, None, out, log_to_mlflow=False)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    assert {p.name for p in first.files} < set(before) and "notes.txt" in before
    real = report_build.write_bytes_atomic
    calls = []

    def full_disk(path, data):
        calls.append(path)
        if len(calls) == 3:
            raise OSError(28, "No space left on device", str(path))
        real(path, data)

    monkeypatch.setattr(report_build, "write_bytes_atomic", full_disk)
    with pytest.raises(OSError, match="No space left on device"):
        build_report(written.uri, None, out, log_to_mlflow=False)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert not list(tmp_path.glob(".out.new-*"))  # no staging folder left behind


def test_every_report_figure_is_readable_at_page_width(loaded):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    from linkevo.orchestrator.report.build import report_figures

    made = report_figures(loaded)
    assert {m.name for m in made} >= {"best_loss", "repertoire_maps", "paths_Fp", "convergence"}
    for item in made:
        FigureCanvasAgg(item.figure).draw()  # ticks and their labels exist once drawn
        scale = min(1.0, fig.PAGE_WIDTH_IN / item.figure.get_figwidth())
        texts = [t for t in item.figure.findobj(Text) if t.get_visible() and t.get_text().strip()]
        assert texts
        smallest = min(t.get_fontsize() for t in texts) * scale
        assert smallest >= fig.MIN_FONT_PT, (item.name, smallest)
    maps = next(m for m in made if m.name == "repertoire_maps")
    titles = [ax.get_title() for ax in maps.figure.axes if ax.get_title()]
    assert any("MAP-AU" in t and "POOLED" in t for t in titles) == ("MAP-AU" in SPEC.approaches)
    # every map pools its trials and says so, with a trial's own coverage beside it
    assert titles and all("POOLED over" in t and "each trial" in t for t in titles)
    boxes = next(m for m in made if m.name == "best_loss")
    assert all("lower is better" in ax.get_ylabel() for ax in boxes.figure.axes if ax.get_ylabel())


def test_a_walking_grids_winners_are_tabled_with_the_ones_to_doubt_named():
    from linkevo.orchestrator.report.checks import walking_winners
    from linkevo.orchestrator.report.html import winners_html
    from linkevo.orchestrator.report.load import WALK_MEASURES, GridData

    sound = dict.fromkeys(WALK_MEASURES, 50.0) | {
        "best_models_agree": 1.0,
        "best_chaotic": 0.0,
        "best_slides": 0.0,
    }
    rows = [
        {"trial_key": "MAP-LIS/Fw/00", "approach": "MAP-LIS", "fitness": "Fw", **sound},
        {
            "trial_key": "NSGA2/Fw/00",
            "approach": "NSGA2",
            "fitness": "Fw",
            **sound,
            "best_slides": 1.0,
            "best_models_agree": 0.0,
        },
        {"trial_key": "EA/Fp/00", "approach": "EA", "fitness": "Fp"},
    ]
    trials = pd.DataFrame(rows).assign(status="FINISHED", best_loss=-50.0)
    grid = GridData("g", "p", "sqlite://", {}, trials, pd.DataFrame())
    winners = walking_winners(grid)
    assert list(winners.trial_key) == ["NSGA2/Fw/00", "MAP-LIS/Fw/00"]  # the study's order
    page = winners_html(winners)
    assert (
        "<li>NSGA2/Fw/00: the full model disagrees with the lean one; its distance is mostly "
        "its feet sliding</li>" in page
    )
    assert "MAP-LIS/Fw/00:" not in page


def test_findings_recompute_from_a_report_folder_and_take_a_reruns_measures(grid, tmp_path, capsys):
    """A report's folder judges its claims again from its tables alone; a copy whose
    trials.csv predates the per-trial measures gets them from a rerun's table, and then
    judges as the report did; a rerun that logged other numbers gives nothing."""
    import shutil

    from linkevo.orchestrator.report.findings import MEASURES

    _, result = grid
    assert main(["findings", str(result.out_dir)]) == 0
    assert f"{result.out_dir / 'findings.csv'}: the same" in capsys.readouterr().out
    old = tmp_path / "old"
    shutil.copytree(result.out_dir, old)
    full = pd.read_csv(result.out_dir / "trials.csv")
    assert full.stagnation.notna().sum() > 0 and full.front_size.notna().sum() > 0
    full.drop(columns=list(MEASURES)).to_csv(old / "trials.csv", index=False)
    assert main(["findings", str(old)]) == 0
    out = capsys.readouterr().out
    assert "differs on 6 Fp" in out and "[not testable] 7" in out

    rerun = tmp_path / "rerun.csv"
    changed = full.copy()
    changed.loc[3, "best_loss"] += 1e-12
    changed.to_csv(rerun, index=False)
    args = ["findings", str(old), "--measures-from", str(rerun), "--write"]
    assert main(args) == 2
    assert f"trial {full.trial_key[3]}: the rerun logged best_loss" in capsys.readouterr().err
    assert "stagnation" not in pd.read_csv(old / "trials.csv")

    halves = [tmp_path / "a.csv", tmp_path / "b.csv"]
    full.iloc[::2].to_csv(halves[0], index=False)
    full.iloc[1::2].to_csv(halves[1], index=False)
    args = ["findings", str(old), "--write"]
    assert main([*args, "--measures-from", str(halves[0]), "--measures-from", str(halves[1])]) == 0
    assert f"{old / 'findings.csv'}: the same" in capsys.readouterr().out
    pd.testing.assert_frame_equal(pd.read_csv(old / "trials.csv"), full)
    assert (old / "findings.csv").read_text() == (result.out_dir / "findings.csv").read_text()
    assert main(["findings", str(tmp_path / "nowhere")]) == 2
    assert "holds no trials.csv" in capsys.readouterr().err


def test_grids_split_by_approach_report_as_one_study(tmp_path, capsys):
    """Two grids of one study, split by approach, give one report: each trial as its own
    grid's report has it, claims judged across both, logged in the first's parent run;
    grids that compute differently, or hold one trial twice, are refused by name."""
    left = write_grid(tmp_path / "a", GridSpec(grid_id="g0left", approaches=("EA", "NSGA2")))
    spec = GridSpec(grid_id="g0right", approaches=("MAP-WH", "MAP-ST"))
    write_grid(tmp_path / "b", spec, server_uri=left.uri)
    out = tmp_path / "both"
    args = ["report", "g0left", "--with", "g0right", "--tracking-uri", left.uri, "--out", str(out)]
    assert main(args) == 0
    assert "grid g0left+g0right: report at" in capsys.readouterr().out
    both = pd.read_csv(out / "trials.csv")
    apart = [
        build_report(left.uri, g, tmp_path / g, log_to_mlflow=False) for g in ("g0left", "g0right")
    ]
    each = pd.concat([pd.read_csv(r.out_dir / "trials.csv") for r in apart], ignore_index=True)
    pd.testing.assert_frame_equal(both, each)
    verdicts = pd.read_csv(out / "findings.csv", dtype=str).set_index(["number", "fitness"]).verdict
    assert verdicts["1", "Fp"] != NOT_TESTABLE  # MAP-WH against the EA: across the grids
    logged = MlflowClient(tracking_uri=left.uri).list_artifacts(left.parent_run_id, "report")
    assert "report/findings.csv" in {a.path for a in logged}

    cheap = GridSpec(grid_id="g0cheap", approaches=("MAP-LIS",), budget=1000)
    write_grid(tmp_path / "c", cheap, server_uri=left.uri)
    assert main([*args[:3], "g0cheap", *args[4:6], "--out", str(tmp_path / "x")]) == 2
    assert "grids g0left and g0cheap differ in evaluations" in capsys.readouterr().err
    assert main([*args[:3], "g0left", *args[4:6], "--out", str(tmp_path / "y")]) == 2
    twice = re.search(r"trial (\S+) is in more than one of the grids", capsys.readouterr().err)
    assert twice and twice.group(1) in set(left.run_ids)
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
